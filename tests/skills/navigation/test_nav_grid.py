from __future__ import annotations

import math

import numpy as np
import pytest

from mmexec.config.yamlload import InputError
from mmexec.drivers.interfaces import OccupancyGrid, Pose2D
from mmexec.drivers.maps import load_map
from mmexec.skills.navigation.grid import cell_to_world, inflate, world_to_cell

_ORIGIN = Pose2D(-1.0, 2.0, 0.0)


def _grid(h=20, w=30, res=0.1, origin=_ORIGIN):
    return OccupancyGrid(np.zeros((h, w), dtype=np.int8), res, origin)


def test_world_cell_round_trip_and_edges():
    g = _grid()
    assert world_to_cell(g, -1.0, 2.0) == (0, 0)
    assert world_to_cell(g, -0.95, 2.05) == (0, 0)
    assert world_to_cell(g, -0.9001, 2.0) == (0, 0)
    assert world_to_cell(g, -0.9, 2.1) == (1, 1)
    assert world_to_cell(g, -1.01, 2.0) == (0, -1)
    x, y = cell_to_world(g, 3, 7)
    assert (x, y) == pytest.approx((-1.0 + 0.75, 2.0 + 0.35))
    assert world_to_cell(g, x, y) == (3, 7)


def test_rotated_origin():
    g = _grid(origin=Pose2D(1.0, 1.0, math.pi / 2))
    # grid +x is map +y
    x, y = cell_to_world(g, 0, 4)
    assert (x, y) == pytest.approx((1.0 - 0.05, 1.0 + 0.45))
    assert world_to_cell(g, x, y) == (0, 4)


def test_inflation_matches_brute_force():
    rng = np.random.default_rng(3)
    data = np.zeros((40, 50), dtype=np.int8)
    data[rng.random(data.shape) < 0.02] = 100
    data[5:8, 10:30] = 100
    data[30, 40] = -1
    g = OccupancyGrid(data, 0.05)
    radius, margin = 0.18, 0.02
    cm = inflate(g, radius, margin)
    obst = np.argwhere((data >= 50) | (data < 0))
    rr, cc = np.mgrid[0:40, 0:50]
    d2 = (rr[..., None] - obst[:, 0]) ** 2 + (cc[..., None] - obst[:, 1]) ** 2
    dmin = np.sqrt(d2.min(axis=2)) * 0.05
    expected = dmin <= radius + margin + 1e-9
    assert np.array_equal(cm.blocked, expected)
    np.testing.assert_allclose(cm.clearance, dmin, atol=1e-4)
    # unknown cells free when asked
    cm2 = inflate(g, 0.0, unknown_is_obstacle=False)
    assert not cm2.blocked[30, 40]
    assert cm.blocked[30, 40]


def test_inflation_empty_grid_and_bad_radius():
    cm = inflate(_grid(), 0.2)
    assert not cm.blocked.any()
    assert cm.is_free(0.0, 3.0)
    assert not cm.is_free(-5.0, 0.0)  # off the map
    with pytest.raises(ValueError):
        inflate(_grid(), -0.1)


def _write_map(tmp_path, yaml_text, pixels):
    h, w = pixels.shape
    (tmp_path / "m.pgm").write_bytes(b"P5\n# comment\n%d %d\n255\n" % (w, h) + pixels.astype(np.uint8).tobytes())
    p = tmp_path / "m.yaml"
    p.write_text(yaml_text)
    return p


def test_load_map_server_map(tmp_path):
    img = np.full((4, 5), 254, dtype=np.uint8)  # free
    img[0, 0] = 0        # top-left black: occupied, lands in the last grid row
    img[3, 4] = 205      # grey: unknown, bottom row -> grid row 0
    p = _write_map(tmp_path, "image: m.pgm\nresolution: 0.05\norigin: [-1.0, -2.0, 0.0]\n", img)
    g = load_map(p)
    assert g.data.shape == (4, 5)
    assert g.data[3, 0] == 100
    assert g.data[0, 4] == -1
    assert (g.data == 0).sum() == 18
    assert g.resolution == 0.05 and g.origin == Pose2D(-1.0, -2.0, 0.0)


def test_load_map_negate(tmp_path):
    img = np.zeros((2, 2), dtype=np.uint8)
    img[0, 0] = 255
    p = _write_map(tmp_path, "image: m.pgm\nresolution: 0.1\norigin: [0, 0, 0]\nnegate: 1\n", img)
    g = load_map(p)
    assert g.data[1, 0] == 100 and g.data[0, 0] == 0


def test_load_map_errors_name_file_line_col(tmp_path):
    img = np.zeros((2, 2), dtype=np.uint8)
    p = _write_map(tmp_path, "image: m.pgm\nresolution: fine\norigin: [0, 0, 0]\n", img)
    with pytest.raises(InputError) as e:
        load_map(p)
    assert f"{p}:2:13: resolution: expected a number" in str(e.value)
    p = _write_map(tmp_path, "image: m.pgm\nresolutoin: 0.1\norigin: [0, 0, 0]\n", img)
    with pytest.raises(InputError) as e:
        load_map(p)
    assert "2:1: resolutoin: unknown key; did you mean 'resolution'?" in str(e.value)
    p = _write_map(tmp_path, "image: missing.pgm\nresolution: 0.1\norigin: [0, 0]\n", img)
    with pytest.raises(InputError) as e:
        load_map(p)
    assert "3:9: origin: expected a list of 3 numbers" in str(e.value)
    p = _write_map(tmp_path, "image: missing.pgm\nresolution: 0.1\norigin: [0, 0, 0]\n", img)
    with pytest.raises(InputError) as e:
        load_map(p)
    assert f"{p}:1:8: image: no such file" in str(e.value)
    (tmp_path / "bad.pgm").write_bytes(b"P6\n2 2\n255\n" + bytes(12))
    p.write_text("image: bad.pgm\nresolution: 0.1\norigin: [0, 0, 0]\n")
    with pytest.raises(InputError) as e:
        load_map(p)
    assert "bad.pgm:1:1: not a PGM image" in str(e.value)


@pytest.mark.parametrize("theta", [0.0, 0.4])
def test_nearest_free_matches_a_brute_force_search(theta):
    """CostMap.nearest_free returns the closest free cell centre within the distance
    (origin rotated too), the point itself when free, None when nothing is near."""
    data = np.zeros((40, 40), np.int8)
    data[15:25, 15:25] = 100
    grid = OccupancyGrid(data, 0.05, Pose2D(-0.3, 0.7, theta))
    cm = inflate(grid, 0.1)
    centre = cell_to_world(grid, 20, 20)
    edge = cell_to_world(grid, 20, 13)  # in the inflation, 2 cells outside the obstacle
    for x, y, dmax in [(*centre, 0.5), (*edge, 0.3), (*edge, 0.04)]:
        best, best_d = None, math.inf
        for r in range(grid.height):
            for c in range(grid.width):
                wx, wy = cell_to_world(grid, r, c)
                d = math.hypot(wx - x, wy - y)
                if not cm.blocked[r, c] and d <= dmax and d < best_d - 1e-12:
                    best, best_d = (wx, wy), d
        got = cm.nearest_free(x, y, dmax)
        if best is None:
            assert got is None
        else:
            assert got is not None and cm.is_free(*got)
            assert math.hypot(got[0] - x, got[1] - y) == pytest.approx(best_d, abs=1e-9)
    free = cell_to_world(grid, 2, 2)
    assert cm.nearest_free(free[0], free[1], 0.3) == free
    assert cm.nearest_free(*centre, 0.2) is None  # the obstacle is 0.25 m deep plus 0.1 m inflation
