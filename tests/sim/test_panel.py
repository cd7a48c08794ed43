"""The simulated control panel (sim/panel.py): the world file's panels: section (checks,
randomised pose, static parts in the map but not in the planning scene) and the physics
of a button: a cap pushed past 70 % of its travel latches its light and springs back,
and each press is measured (deepest travel, the press point's offset from the centre)."""

from __future__ import annotations

import math

import numpy as np
import pybullet as p
import pytest

from mmexec.config.yamlload import InputError
from mmexec.drivers.geometry import position_quat
from mmexec.sim.panel import PRESS_FRACTION, SimPanels
from mmexec.sim.scene import spawn_world
from mmexec.sim.world import load_world

PANEL = """
name: t
room: {size: [4.0, 3.0]}
panels:
  - name: p
    pose: [3.0, 1.0, 3.14159265]
    buttons:
      - {name: a, position: [-0.1, -0.03], diameter: 0.02, light: [-0.1, 0.05]}
      - {name: b, position: [0.1, -0.03], diameter: 0.04, light: [0.1, 0.05]}
    markers: [{id: 10, position: [-0.16, 0.11]}, {id: 11, position: [0.16, 0.11]}, {id: 12, position: [0.0, -0.11]}]
    locator: {id: 20}
"""


def _world(tmp_path, text=PANEL, **kw):
    f = tmp_path / "w.yaml"
    f.write_text(text)
    return load_world(str(f), **kw)


def test_lab_panel_geometry_map_and_scene():
    w = load_world("lab")
    (pn,) = w.spec.panels
    T = w.panel_poses["panel"]
    assert [b.name for b in pn.buttons] == ["b1", "b2", "b3"] and [b.diameter for b in pn.buttons] == [0.02, 0.03, 0.04]
    assert sorted(pn.marker_ids()) == [10, 11, 12, 13, 14, 15, 16, 20]
    assert T[:3, 3] == pytest.approx([4.3, 0.55, 0.75]) and T[:3, 1] == pytest.approx([0, 0, 1])
    assert math.atan2(T[1, 2], T[0, 2]) == pytest.approx(3 * math.pi / 4)  # the face looks into the room
    kinds = {n: k for n, _, _, k in w.static_boxes()}
    assert kinds["panel_box"] == kinds["panel_stand"] == "panel"
    assert not any(b.name.startswith("panel_") for b in w.scene_boxes())  # the robot adds what it sees
    g = w.occupancy(0.05)
    stand = T[:3, 3] - 0.075 * T[:3, 2]
    assert g.data[int((stand[1] - g.origin.y) / 0.05), int((stand[0] - g.origin.x) / 0.05)] == 100


def test_randomised_panel_pose_is_seeded_and_bounded():
    a = load_world("lab", seed=3, randomize=True).panel_poses["panel"]
    assert np.array_equal(a, load_world("lab", seed=3, randomize=True).panel_poses["panel"])
    yaws = []
    for seed in range(20):
        T = load_world("lab", seed=seed, randomize=True).panel_poses["panel"]
        assert math.hypot(T[0, 3] - 4.3, T[1, 3] - 0.55) <= 0.05 * math.sqrt(2) + 1e-9
        yaws.append(math.atan2(T[1, 2], T[0, 2]) - 3 * math.pi / 4)
    assert max(map(abs, yaws)) <= math.radians(30) + 1e-9 and max(yaws) - min(yaws) > math.radians(20)
    # the panel draws from its own stream: the items and the start are what they were
    w = load_world("lab", seed=3, randomize=True)
    assert w.start == load_world("lab", seed=3, randomize=True).start


@pytest.mark.parametrize("old, new, msg", [
    ("{id: 12, position: [0.0, -0.11]}]", "{id: 11, position: [0.0, -0.11]}]", "marker ids must be unique"),
    ("room: {size: [4.0, 3.0]}", "room: {size: [4.0, 3.0]}\nitems: [{name: x, marker: 12, pose: [1, 1, 0.5, 0]}]",
     "marker 12 already used by 'x'"),
    ("{id: 12, position: [0.0, -0.11]}]", "{id: 12, position: [0.19, 0.11]}]", "marker 12 at \\[0.19, 0.11\\] does not fit"),
])
def test_bad_panels_are_located(tmp_path, old, new, msg):
    text = PANEL.replace(old, new)
    with pytest.raises(InputError, match=msg) as e:
        _world(tmp_path, text)
    assert "w.yaml:" in str(e.value)


@pytest.fixture
def pushed(tmp_path):
    """The test panel spawned alone, and a 1 cm finger on a prismatic joint along the
    face normal 2 mm right of button b's centre, ready to push it."""
    w = _world(tmp_path)
    cid = p.connect(p.DIRECT)
    p.setGravity(0, 0, -9.81, physicsClientId=cid)
    p.setTimeStep(1 / 240, physicsClientId=cid)
    h = spawn_world(w, cid)
    T = w.panel_poses["p"]
    start = T @ np.array([0.1 + 0.002, -0.03, 0.04, 1.0])  # its end 15 mm above the cap
    _, quat = position_quat(T)
    col = p.createCollisionShape(p.GEOM_BOX, halfExtents=[0.005, 0.005, 0.01], physicsClientId=cid)
    finger = p.createMultiBody(0, -1, -1, start[:3].tolist(), quat, linkMasses=[0.1], linkCollisionShapeIndices=[col],
                               linkVisualShapeIndices=[-1], linkPositions=[[0, 0, 0]], linkOrientations=[[0, 0, 0, 1]],
                               linkInertialFramePositions=[[0, 0, 0]], linkInertialFrameOrientations=[[0, 0, 0, 1]],
                               linkParentIndices=[0], linkJointTypes=[p.JOINT_PRISMATIC], linkJointAxis=[[0, 0, -1]],
                               physicsClientId=cid)
    yield cid, h.panels, finger
    p.disconnect(cid)


def _drive(cid, panels, finger, target, seconds, t0=0.0):
    p.setJointMotorControl2(finger, 0, p.POSITION_CONTROL, targetPosition=target, force=50, maxVelocity=0.05,
                            physicsClientId=cid)
    for k in range(int(seconds * 240)):
        p.stepSimulation(physicsClientId=cid)
        panels.step(t0 + (k + 1) / 240)
    return t0 + seconds


def test_a_press_past_70_percent_latches_the_light_and_is_measured(pushed):
    cid, panels, finger = pushed
    assert isinstance(panels, SimPanels) and panels.lights() == {"p/a": False, "p/b": False}
    # the finger's end starts 15 mm above the cap (cap 15 mm out of the face); push 3 mm in: not switched
    t = _drive(cid, panels, finger, 0.015 + 0.003, 1.0)
    t = _drive(cid, panels, finger, 0.0, 1.0, t)
    assert panels.lights()["p/b"] is False
    (first,) = panels.drain()
    assert not first.switched and 0.0025 < first.depth < 0.0035
    # 8 mm in: past 70 % of the 6 mm travel, light on; released, the cap springs back
    t = _drive(cid, panels, finger, 0.015 + 0.008, 1.0, t)
    assert panels.lights() == {"p/a": False, "p/b": True}
    t = _drive(cid, panels, finger, 0.0, 1.0, t)
    assert panels.at_rest() and panels.lights()["p/b"] is True  # it latches
    (second,) = panels.drain()
    assert second.switched and second.depth >= PRESS_FRACTION * 0.006 and second.depth < 0.0105
    assert second.offset == pytest.approx(0.002, abs=0.0007)  # the finger's centre, 2 mm right of the cap's
    rec = second.record()
    assert rec["button"] == "b" and rec["switched"] and rec["offset_mm"] == pytest.approx(2.0, abs=0.7)
