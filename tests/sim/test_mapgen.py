"""``mmexec.sim.mapgen``: a world's static geometry as a map_server map and ``robot.scene``
lines; the shipped ``config/maps/lab.*`` is what it generates from ``sim/worlds/lab.yaml``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mmexec.config.yamlload import load_yaml_text
from mmexec.drivers import maps
from mmexec.drivers.interfaces import OccupancyGrid, Pose2D
from mmexec.drivers.maps import load_map, read_pgm
from mmexec.drivers.robot import pose_matrix
from mmexec.sim import mapgen
from mmexec.sim.world import load_world

REPO = Path(__file__).resolve().parents[2]


def within_a_cell(a: np.ndarray, b: np.ndarray) -> bool:
    """Every occupied cell of each grid has an occupied cell of the other within one cell
    (8-neighbourhood), and both have the same shape."""
    if a.shape != b.shape:
        return False

    def grow(m: np.ndarray) -> np.ndarray:
        p = np.pad(m, 1)
        return np.logical_or.reduce([p[1 + dr: 1 + dr + m.shape[0], 1 + dc: 1 + dc + m.shape[1]]
                                     for dr in (-1, 0, 1) for dc in (-1, 0, 1)])

    oa, ob = a >= 50, b >= 50
    return bool(not (oa & ~grow(ob)).any() and not (ob & ~grow(oa)).any())


@pytest.mark.parametrize("world", ["lab", "bench"])
def test_the_map_round_trips_through_load_map(tmp_path: Path, bench_world: str, world: str) -> None:
    w = load_world(bench_world if world == "bench" else world)
    grid = mapgen.world_map(w)
    sim = w.occupancy(0.05)  # what the sim backend puts on Robot.occupancy
    assert np.array_equal(grid.data, sim.data)
    yaml_path, pgm_path = maps.write_map(grid, tmp_path / "maps" / f"{world}.yaml", comment="test\nmap")
    assert pgm_path == tmp_path / "maps" / f"{world}.pgm" and pgm_path.exists()
    back = load_map(yaml_path)
    assert back.resolution == pytest.approx(0.05)
    assert (back.origin.x, back.origin.y, back.origin.theta) == pytest.approx((sim.origin.x, sim.origin.y, 0.0))
    assert back.data.dtype == sim.data.dtype and np.array_equal(back.data, sim.data)
    assert set(np.unique(back.data)) == {0, 100}


def test_unknown_cells_and_the_picture_layout(tmp_path: Path) -> None:
    data = np.zeros((3, 4), dtype=np.int8)
    data[0, 0] = 100   # bottom-left of the map: last picture row
    data[2, 3] = -1    # top-right: first picture row, grey
    grid = OccupancyGrid(data=data, resolution=0.1, origin=Pose2D(1.0, -2.0, 0.0))
    yaml_path, pgm_path = maps.write_map(grid, tmp_path / "m.yaml")
    img = read_pgm(pgm_path)
    assert img.shape == (3, 4)
    assert img[2, 0] == maps.OCCUPIED and img[0, 3] == maps.UNKNOWN and img[1, 1] == maps.FREE
    back = load_map(yaml_path)
    assert np.array_equal(back.data, data)
    assert (back.origin.x, back.origin.y) == pytest.approx((1.0, -2.0))
    with pytest.raises(ValueError, match="rotated origin"):
        maps.write_map(OccupancyGrid(data=data, resolution=0.1, origin=Pose2D(0, 0, 0.5)), tmp_path / "r.yaml")


def test_scene_lines_rebuild_the_worlds_scene_boxes() -> None:
    w = load_world("lab")
    text = mapgen.scene_yaml(w, indent=2)
    entries = load_yaml_text("scene:\n" + text, "scene.yaml")["scene"]
    boxes = w.scene_boxes()
    assert [e["name"] for e in entries] == [b.name for b in boxes]
    for e, b in zip(entries, boxes):
        assert tuple(e["size"]) == pytest.approx(b.size, abs=1e-6)
        assert pose_matrix(tuple(e["xyz"]), tuple(e["rpy"])) == pytest.approx(b.pose, abs=1e-6)


def test_the_shipped_lab_map_is_the_generated_one(tmp_path: Path) -> None:
    shipped = REPO / "config" / "maps" / "lab.yaml"
    assert (REPO / "config" / "maps" / "lab.pgm").stat().st_size < 10_000   # a 5.2 x 4.2 m grid at 0.05 m
    grid = load_map(shipped)
    sim = load_world("lab").occupancy(0.05)
    assert grid.resolution == pytest.approx(sim.resolution)
    assert (grid.origin.x, grid.origin.y, grid.origin.theta) == pytest.approx((sim.origin.x, sim.origin.y, 0.0))
    assert within_a_cell(grid.data, sim.data)
    # and main() (the script that wrote it) writes the same cells and prints the scene
    out = tmp_path / "lab.yaml"
    assert mapgen.main(["lab", str(out)]) == 0
    assert np.array_equal(load_map(out).data, grid.data)


def test_main_prints_the_scene(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert mapgen.main(["lab", str(tmp_path / "x.yaml")]) == 0
    out = capsys.readouterr().out
    assert out.startswith("  scene:")
    assert "- {name: shelf_far_board0, size: [0.35, 0.96, 0.02], xyz: [4.78, 2, 0.24], rpy: [0, 0, 3.141593]}" in out
