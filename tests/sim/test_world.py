"""World loading, located errors, randomisation, occupancy and planning scene."""

from __future__ import annotations

import re

import numpy as np
import pytest

from mmexec.config.yamlload import InputError
from mmexec.sim.world import load_world, shipped_worlds


def test_lab_has_six_tagged_boxes_two_shelves_depot():
    w = load_world("lab")
    assert "lab" in shipped_worlds()
    assert sorted(w.marker_of(n) for n in w.item_names()) == [1, 2, 3, 4, 5, 6]
    assert len(w.spec.shelves) == 2 and len(w.spec.depots) == 1 and len(w.obstacles) >= 2
    sx, sy = w.spec.room.size
    assert 18.0 <= sx * sy <= 22.0
    # marker faces (item +x) point into the room, away from the wall behind the shelf
    for n in w.item_names():
        T = w.item_poses[n]
        ahead = T[:3, 3] + 0.5 * T[:3, 0]
        assert 0 < ahead[0] < sx and 0 < ahead[1] < sy, n
    # some boxes start behind the robot (start faces +x)
    behind = [n for n in w.item_names() if w.item_poses[n][0, 3] < w.start.x]
    assert behind


def test_occupancy_marks_walls_shelves_obstacles_and_frees_start():
    w = load_world("lab")
    g = w.occupancy(0.05)
    def cell(x, y):
        return g.data[int((y - g.origin.y) / g.resolution), int((x - g.origin.x) / g.resolution)]
    assert cell(w.start.x, w.start.y) == 0
    assert cell(-0.05, 2.0) == 100          # west wall
    assert cell(4.78, 2.0) == 100           # far shelf footprint
    assert cell(3.1, 2.85) == 100           # crate obstacle
    assert cell(2.0, 2.0) == 0
    assert g.data.dtype == np.int8 and set(np.unique(g.data)) <= {0, 100}


def test_scene_boxes_include_shelf_boards_at_their_heights():
    w = load_world("lab")
    boards = {b.name: b for b in w.scene_boxes() if "board" in b.name}
    assert len(boards) == 4
    top = boards["shelf_far_board1"]
    assert top.pose[2, 3] + top.size[2] / 2 == pytest.approx(0.5)


def test_randomize_is_seeded():
    a = load_world("lab", seed=7, randomize=True)
    b = load_world("lab", seed=7, randomize=True)
    c = load_world("lab", seed=8, randomize=True)
    assert a.start == b.start and a.start != c.start
    assert all(np.array_equal(a.item_poses[n], b.item_poses[n]) for n in a.item_names())
    assert any(not np.allclose(a.item_poses[n], c.item_poses[n]) for n in a.item_names())
    plain = load_world("lab", seed=7)
    assert plain.start.x == 1.5 and plain.start.theta == 0.0


BASE = """name: t
room: {size: [4.0, 3.0]}
shelves:
  - {name: s1, pose: [3.8, 1.5, 3.14]}
items:
  - {name: a, marker: 1, shelf: s1}
"""


@pytest.mark.parametrize("text, line, col, msg", [
    (BASE + "colour: red\n", 7, 1, r"colour: unknown key"),
    (BASE.replace("shelf: s1}", "shelf: s2}"), 6, 33, r"no shelf 's2' \(shelves: s1\)"),
    (BASE.replace("marker: 1", "marker: one"), 6, 23, r"items\[0\]\.marker: expected an integer"),
    (BASE + "  - {name: b, marker: 1, shelf: s1, offset: 0.2}\n", 7, 23, r"id 1 already used by 'a'"),
    (BASE.replace("shelf: s1}", "shelf: s1, board: 5}"), 6, 44, r"boards 0\.\.1, got 5"),
    (BASE.replace("room: {size: [4.0, 3.0]}", "room: {size: [4.0, 3.0}"), 2, 23, r"malformed YAML"),
    (BASE.replace("pose: [3.8, 1.5, 3.14]", "pose: [3.8, 1.5]"), 4, 22, r"expected a list of 3 numbers"),
    (BASE + "start: [9.0, 1.0, 0.0]\n", 7, 8, r"outside the 4.0 x 3.0 m room"),
])
def test_bad_worlds_report_file_line_col(tmp_path, text, line, col, msg):
    f = tmp_path / "bad.yaml"
    f.write_text(text)
    with pytest.raises(InputError) as e:
        load_world(str(f))
    first = str(e.value).splitlines()[0]
    assert first.startswith(f"{f}:{line}:{col}: "), first
    assert re.search(msg, first), first


def test_unknown_world_name_suggests():
    with pytest.raises(InputError, match=r"unknown world 'lib'.*did you mean 'lab'"):
        load_world("lib")


def test_missing_world_file():
    with pytest.raises(InputError, match=r"nope\.yaml:1:1: no such file"):
        load_world("/tmp/definitely/nope.yaml")
