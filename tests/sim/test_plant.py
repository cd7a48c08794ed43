"""The plants of sim/plant.py: fruit drawn inside the world file's ranges and apart, the
magnets (breakable constraints) that hold a fruit against gravity and let go above the
break force, the basket on the robot carrying what lies in it, the marker-tagged depot,
and the truth records."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pybullet as p
import pytest

from mmexec.config.yamlload import InputError
from mmexec.drivers.interfaces import Pose2D
from mmexec.sim.backend import build
from mmexec.sim.plant import BREAK_DISTANCE, STEM
from mmexec.sim.world import load_world

SECTION = "robot: ur5e_robotiq\nworld: lab\nphysics_hz: 120\nbasket: {xyz: [-0.205, 0.0, 0.40], size: [0.20, 0.46, 0.12]}\n"


@pytest.fixture
def robot(sim_section):
    r = build(sim_section(SECTION), profile={}, seed=3, options={})
    yield r
    r.close()


def test_fruit_are_drawn_inside_the_ranges_apart_and_reproducibly():
    spec = load_world("lab").spec.plants[0]
    draws = [load_world("lab", seed=s, randomize=True).plants[0] for s in range(8)]
    assert load_world("lab").plants == load_world("lab").plants  # fixed without randomisation
    assert len({tuple(f.centre for f in d.fruit) for d in draws}) == 8  # each seed draws its own plant
    x0, y0, front = spec.pose
    for d in draws:
        assert spec.fruit_count[0] <= len(d.fruit) <= spec.fruit_count[1]
        for f in d.fruit:
            assert spec.fruit_radius[0] <= f.radius <= spec.fruit_radius[1]
            assert spec.fruit_height[0] <= f.centre[2] <= spec.fruit_height[1]
            ring = math.hypot(f.centre[0] - x0, f.centre[1] - y0)
            assert spec.fruit_ring[0] <= ring <= spec.fruit_ring[1]
            bearing = math.atan2(f.centre[1] - y0, f.centre[0] - x0) - front
            assert abs(math.atan2(math.sin(bearing), math.cos(bearing))) <= spec.fruit_sector / 2 + 1e-9
            assert f.anchor[2] == pytest.approx(f.centre[2] + f.radius + STEM)
        for i, a in enumerate(d.fruit):
            for b in d.fruit[i + 1:]:
                assert math.dist(a.centre, b.centre) >= a.radius + b.radius + spec.fruit_gap


def test_a_bad_plant_is_a_located_error(tmp_path: Path):
    w = tmp_path / "w.yaml"
    w.write_text("name: w\nroom: {size: [3, 3]}\nplants:\n  - {name: p, pose: [1, 1, 0], fruit_radius: [0.03, 0.07],\n"
                 "     break_force: 0.5}\n")
    with pytest.raises(InputError) as e:
        load_world(w)
    text = str(e.value)
    assert f"{w}:4:" in text and "fruit_radius must lie in [0.03, 0.05]" in text and "break_force 0.5 N" in text


def test_the_magnets_hold_every_fruit_against_gravity(robot):
    plants = robot.scene_handles.plants
    robot.spin(2.0)
    for name, f in plants.fruit.items():
        assert plants.states[name] == "plant"
        assert np.linalg.norm(plants.position(name) - np.array(f.centre)) < 0.004


def _pull(robot, name: str, force: float, seconds: float) -> None:
    plants = robot.scene_handles.plants
    body = plants.bodies[name]
    dt = 1.0 / robot.clock.hz
    for _ in range(round(seconds / dt)):
        pos = p.getBasePositionAndOrientation(body, physicsClientId=robot.cid)[0]
        p.applyExternalForce(body, -1, [force, 0.0, 0.0], pos, p.WORLD_FRAME, physicsClientId=robot.cid)
        robot.spin(dt)


def test_a_pull_above_the_break_force_takes_the_fruit_off_and_one_below_does_not(robot):
    plants = robot.scene_handles.plants
    first, second = list(plants.fruit)[:2]
    force = robot.world.spec.plants[0].break_force
    _pull(robot, first, 0.5 * force, 1.0)
    # it swings out on its stem (a pendulum) but the stem stays on the magnet
    assert plants.states[first] == "plant" and first not in plants.broken
    assert np.linalg.norm(plants.position(first) - np.array(plants.fruit[first].centre)) > BREAK_DISTANCE
    _pull(robot, second, 3.0 * force, 0.5)
    assert second in plants.broken
    robot.spin(2.0)
    assert plants.states[second] == "floor"
    assert plants.states[first] == "plant"


def test_the_basket_on_the_robot_carries_a_fruit_lying_in_it(robot):
    plants = robot.scene_handles.plants
    name = next(iter(plants.fruit))
    body = plants.bodies[name]
    _pull(robot, name, 30.0, 0.1)  # off its branch
    T_base = robot.core.true_pose.matrix()
    drop = T_base @ np.array([-0.205, 0.0, 0.47, 1.0])
    p.resetBasePositionAndOrientation(body, drop[:3].tolist(), [0, 0, 0, 1], physicsClientId=robot.cid)
    p.resetBaseVelocity(body, [0, 0, 0], [0, 0, 0], physicsClientId=robot.cid)
    robot.spin(1.0)
    assert plants.states[name] == "robot_basket"
    start = robot.core.true_pose
    for _ in range(60):  # 3 s of driving and turning
        robot.base.set_velocity(0.3, 0.4)
        robot.spin(0.05)
    moved = robot.core.true_pose
    assert math.hypot(moved.x - start.x, moved.y - start.y) > 0.3
    assert plants.states[name] == "robot_basket"
    here = np.linalg.inv(moved.matrix()) @ np.append(plants.position(name), 1.0)
    assert abs(here[0] + 0.205) < 0.1 and abs(here[1]) < 0.23 and 0.4 < here[2] < 0.52


def test_the_depot_carries_its_marker_on_the_wall_facing_the_room():
    d = load_world("lab").spec.depots[0]
    T = d.marker_pose()
    assert d.marker == 30 and T is not None
    assert T[:3, 2] == pytest.approx([0.0, -1.0, 0.0])  # out of the south wall, into the room
    assert T[1, 3] == pytest.approx(d.pose[1] - d.size[1] / 2, abs=1e-3)
    assert T[2, 3] == pytest.approx(d.size[2] / 2)


def test_the_truth_log_records_each_fruit_and_its_state_changes(sim_section, tmp_path: Path):
    import json

    section = SECTION + f"truth_log: {tmp_path}/t.jsonl\n"
    r = build(sim_section(section), profile={}, seed=3, options={})
    try:
        name = next(iter(r.scene_handles.plants.fruit))
        _pull(r, name, 30.0, 0.2)
        r.spin(2.0)
    finally:
        r.close()
    recs = [json.loads(line) for line in (tmp_path / "t.jsonl").read_text().splitlines()]
    start = next(x for x in recs if x["event"] == "fruit_start")
    assert len(start["fruit"]) == len(load_world("lab").plants[0].fruit)
    states = [x["state"] for x in recs if x["event"] == "fruit" and x["name"] == name]
    assert states[-1] == "floor" and "plant" not in states


def test_a_world_without_plants_spawns_none(sim_section, bench_world):
    r = build(sim_section(f"world: {bench_world}\n"), profile={}, seed=0, options={})
    try:
        assert r.scene_handles.plants is None
        r.core.place_base(Pose2D(1.0, 1.0, 0.0))
    finally:
        r.close()
