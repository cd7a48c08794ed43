"""Untagged sim objects (sim/objects.py): the world schema, true centres of mass, spawning
into pybullet with one link per part, and the truth helpers."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pybullet as p
import pytest

from mmexec.config.yamlload import InputError
from mmexec.sim.objects import (
    KINDS,
    centre_of_mass,
    object_frame,
    part_centre,
    parts_touched,
    project_point,
    spawn_objects,
)
from mmexec.sim.world import load_world

WORLD = """\
name: t
room: {size: [3.0, 3.0]}
shelves:
  - {name: shelf, pose: [2.8, 1.5, 3.14159265], boards: [0.25, 0.5]}
tables:
  - {name: table, pose: [1.0, 0.5, 0.0], size: [0.9, 0.6, 0.3]}
objects:
  - {name: sd, kind: screwdriver, table: table, position: [1.0, 0.6]}
  - {name: bx, kind: box, shelf: shelf, board: 0, offset: 0.2}
"""


def _world(tmp_path: Path, text: str = WORLD, **kw: object):
    path = tmp_path / "w.yaml"
    path.write_text(text)
    return load_world(path, **kw)  # type: ignore[arg-type]


def test_objects_are_placed_on_their_supports(tmp_path: Path) -> None:
    w = _world(tmp_path)
    assert w.object_names() == ("sd", "bx")
    sd = w.object_poses["sd"]
    assert sd[:3, 3] == pytest.approx([1.0, 0.6, 0.3 + 0.02 + 1e-3])  # lying on the table top
    bx = w.object_poses["bx"]
    assert bx[2, 3] == pytest.approx(0.25 + 0.04 + 1e-3)  # standing on board 0
    assert bx[1, 3] == pytest.approx(1.5 - 0.2)  # offset along the shelf's width (the shelf faces -x)
    # the objects are not in the map or the arm's planning scene: the robot learns of them by looking
    assert all("sd" not in b.name and "bx" not in b.name for b in w.scene_boxes())


def test_a_two_part_objects_centre_of_mass_is_not_its_box_centre() -> None:
    sd = KINDS["screwdriver"]
    com = centre_of_mass(sd)
    blade, handle = part_centre(sd, "blade"), part_centre(sd, "handle")
    # the heavier blade pulls the centre of mass its way, by the mass-weighted mean
    expect = (0.06 * blade + 0.05 * handle) / 0.11
    assert com == pytest.approx(expect)
    assert com[0] > 0.0
    assert [p.name for p in sd.parts if p.dangerous] == ["blade"]
    assert [p.name for p in KINDS["pliers"].parts if p.dangerous] == ["head"]


def test_randomized_objects_draw_their_own_stream(tmp_path: Path) -> None:
    a = _world(tmp_path, seed=3, randomize=True)
    no_objects = WORLD.split("objects:")[0] + "randomize: {item_xy: 0.05, item_yaw: 0.1, start_xy: 0.3}\n"
    b = _world(tmp_path, WORLD.replace("tables:", "randomize: {item_xy: 0.05, item_yaw: 0.1, start_xy: 0.3}\ntables:"),
               seed=3, randomize=True)
    c = _world(tmp_path, no_objects, seed=3, randomize=True)
    assert b.start == c.start  # adding objects changes nothing else the seed draws
    assert not np.allclose(b.object_poses["sd"], a.object_poses["sd"])  # they are randomised


@pytest.mark.parametrize(("line", "message"), [
    ("  - {name: x, kind: screwdrivr, table: table, position: [1.0, 0.5]}", "did you mean 'screwdriver'"),
    ("  - {name: x, kind: pen, table: tabel, position: [1.0, 0.5]}", "no table 'tabel'"),
    ("  - {name: x, kind: pen, shelf: shelf, board: 3}", "boards 0..1"),
    ("  - {name: x, kind: pen, shelf: shelf, board: 0, offset: 0.49}", "does not fit shelf"),
    ("  - {name: x, kind: pen}", "exactly one of shelf, table or pose"),
    ("  - {name: bx, kind: pen, pose: [1, 1, 0.1, 0]}", "already names"),
])
def test_object_mistakes_are_located(tmp_path: Path, line: str, message: str) -> None:
    with pytest.raises(InputError) as e:
        _world(tmp_path, WORLD + line + "\n")
    text = str(e.value)
    assert message in text and "w.yaml:" in text


def test_spawned_objects_have_a_link_per_part_and_their_true_frame(tmp_path: Path) -> None:
    w = _world(tmp_path)
    cid = p.connect(p.DIRECT)
    try:
        bodies = spawn_objects(w.spec.objects, w.object_poses, cid, (4, 0xFF))
        sd = bodies["sd"]
        assert p.getNumJoints(sd, physicsClientId=cid) == 1  # handle = base link, blade on a fixed joint
        T = object_frame(cid, sd, KINDS["screwdriver"])
        assert T == pytest.approx(w.object_poses["sd"], abs=1e-6)
        blade = np.array(p.getLinkState(sd, 0, physicsClientId=cid)[4])
        assert blade == pytest.approx((T @ np.array([*part_centre(KINDS["screwdriver"], "blade"), 1.0]))[:3], abs=1e-6)
    finally:
        p.disconnect(cid)
    objects = {o.name: o for o in w.spec.objects}
    assert parts_touched(objects, "sd", (0,)) == ("blade",)
    assert parts_touched(objects, "sd", (-1, 0)) == ("handle", "blade")
    assert parts_touched(objects, "box_1", (-1,)) == ()  # a marker item is no object


def test_project_point() -> None:
    T = np.eye(4)  # optical frame = map: z forward
    assert project_point(T, 500.0, 500.0, 320.0, 240.0, (0.1, -0.2, 2.0)) == pytest.approx((345.0, 190.0))
    assert project_point(T, 500.0, 500.0, 320.0, 240.0, (0.0, 0.0, -1.0)) is None
    assert math.isfinite(project_point(T, 1.0, 1.0, 0.0, 0.0, (0.0, 0.0, 1.0))[0])  # type: ignore[index]
