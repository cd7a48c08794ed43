"""People and unmapped obstacles in the simulation (issue 12): the world schema, what the
robot is told versus what is there, people walking and giving way, the bumper against a
person, the crowd and clutter faults, and the ground-truth sidecar."""

from __future__ import annotations

import itertools
import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from mmexec.config.yamlload import InputError, load_yaml_text
from mmexec.drivers.interfaces import Pose2D
from mmexec.sim.backend import build
from mmexec.sim.faults import (
    Clutter,
    Crowd,
    FaultConfig,
    _connected,
    _FreeSpace,
    _places,
    world_extras,
)
from mmexec.sim.mapgen import scene_yaml, world_map
from mmexec.sim.people import PATIENCE, YIELD_GAP, SimPeople
from mmexec.sim.world import Person, load_world

ROOM = """name: hall
room: {size: [6.0, 4.0]}
start: [1.0, 2.0, 0.0]
obstacles:
  - {name: known, pose: [5.0, 3.0, 0.0], size: [0.4, 0.4, 0.9]}
  - {name: parcel, pose: [3.0, 2.0, 0.0], size: [0.4, 0.4, 0.9], unmapped: true}
"""


def _world_file(tmp_path: Path, extra: str = "", name: str = "hall.yaml") -> Path:
    path = tmp_path / name
    path.write_text(ROOM + extra)
    return path


def _cell(grid, x: float, y: float) -> int:
    return int(grid.data[int((y - grid.origin.y) / grid.resolution), int((x - grid.origin.x) / grid.resolution)])


# --------------------------------------------------------------------------- schema


def test_an_unmapped_obstacle_is_in_physics_and_lidar_but_not_in_the_map_or_scene(tmp_path, sim_section):
    path = _world_file(tmp_path)
    w = load_world(path)
    assert w.unmapped_names() == {"parcel"}
    grid = w.occupancy(0.05)
    assert _cell(grid, 5.0, 3.0) == 100 and _cell(grid, 3.0, 2.0) == 0
    assert "parcel" not in {b.name for b in w.scene_boxes()} and "known" in {b.name for b in w.scene_boxes()}
    assert "parcel" in {name for name, *_ in w.static_boxes()}
    # mapgen writes what the robot is told
    assert _cell(world_map(w), 3.0, 2.0) == 0 and "parcel" not in scene_yaml(w)
    # the lidar sees it: the beam straight ahead stops at its face, 0.8 m ahead
    robot = build(sim_section(f"world: {path}\nphysics_hz: 60\nlidar: {{noise: 0.0}}\n"), profile={}, seed=1,
                  options={})
    try:
        scan = robot.lidar.scan()
        lidar = robot.core.link_T(robot.core.info.lidar_link)
        ahead = int(np.argmin(np.abs(scan.angles - (0.0 - math.atan2(lidar[1, 0], lidar[0, 0])))))
        assert scan.ranges[ahead] == pytest.approx(2.8 - lidar[0, 3], abs=0.02)
        # and the base bumps into it (a contact recorded with its name)
        for _ in range(200):
            robot.base.set_velocity(0.4, 0.0)
            robot.spin(0.05)
            if robot.base.state().faults:
                break
        assert robot.base.state().faults == {"bumper_centre"}
        assert [c.body for c in robot.core.contacts] == ["parcel"]
    finally:
        robot.close()


def test_people_are_loaded_checked_and_randomised_from_the_seed(tmp_path):
    path = _world_file(tmp_path, """people:
  - {name: ann, waypoints: [[1.0, 1.0], [5.0, 1.0]], speed: 0.8, pause: 1.0}
randomize: {person_xy: 0.2, person_speed: 0.3, person_pause: 2.0, person_delay: 5.0}
""")
    plain = load_world(path)
    assert plain.people == (Person("ann", ((1.0, 1.0), (5.0, 1.0)), speed=0.8, pause=1.0),)
    a, b, c = (load_world(path, seed=s, randomize=True) for s in (3, 3, 4))
    assert a.people == b.people and a.people != c.people
    pa = a.people[0]
    assert 0.3 <= pa.speed <= 1.2 and 1.0 <= pa.pause <= 3.0 and 0.0 <= pa.delay <= 5.0
    assert all(abs(x - x0) <= 0.2 and abs(y - y0) <= 0.2
               for (x, y), (x0, y0) in zip(pa.waypoints, plain.people[0].waypoints))
    # people are drawn last: everything else is what the same seed drew without them
    without = _world_file(tmp_path, "randomize: {person_xy: 0.2}\n", "bare.yaml")
    assert load_world(without, seed=3, randomize=True).start == load_world(path, seed=3, randomize=True).start


@pytest.mark.parametrize(("entry", "message"), [
    ("{name: p, waypoints: [[1, 1]]}", "needs at least 2 points"),
    ("{name: p, waypoints: [[1, 1], [1, 1]]}", "consecutive waypoints are the same point"),
    ("{name: p, waypoints: [[1, 1], [2, 1]], radius: 0.6}", "radius 0.6 m outside"),
    ("{name: p, waypoints: [[1, 1], [2, 1]], speed: 0}", "speed 0 m/s outside"),
    ("{name: p, waypoints: [[1, 1], [9, 1]]}", "people[0].waypoints[1]: 'p' at (9.0, 1.0) is outside"),
    ("{name: known, waypoints: [[1, 1], [2, 1]]}", "already names a obstacle"),
    ("{name: p, waypoints: [[1, 1], [2, 1]], sped: 1.0}", "sped"),
])
def test_bad_people_are_located_errors(tmp_path, entry, message):
    path = _world_file(tmp_path, f"people:\n  - {entry}\n")
    with pytest.raises(InputError) as e:
        load_world(path)
    assert message in str(e.value) and "hall.yaml:" in str(e.value)


# --------------------------------------------------------------------------- walking


def _people(people, robot=(-10.0, -10.0), seconds=0.0, dt=1 / 60):
    """SimPeople in a fresh pybullet client, stepped ``seconds`` with the robot at ``robot``."""
    import pybullet as p

    cid = p.connect(p.DIRECT)
    sp = SimPeople(people, cid)
    for _ in range(round(seconds / dt)):
        sp.step(dt, robot, 0.178)
    return sp, cid


def test_a_person_walks_the_loop_pausing_at_each_waypoint():
    import pybullet as p

    ann = Person("ann", ((1.0, 1.0), (3.0, 1.0)), speed=1.0, pause=0.5)
    sp, cid = _people([ann], seconds=1.0)
    try:
        assert sp.positions()[0] == pytest.approx([2.0, 1.0], abs=0.02)
        for _ in range(60):
            sp.step(1 / 60, (-10.0, -10.0), 0.178)
        assert sp.walks[0].phase == "pause" and sp.positions()[0] == pytest.approx([3.0, 1.0])
        for _ in range(60):  # 0.5 s standing, then 0.5 s back towards the first waypoint
            sp.step(1 / 60, (-10.0, -10.0), 0.178)
        assert sp.positions()[0] == pytest.approx([2.5, 1.0], abs=0.03)
        body_xy = p.getBasePositionAndOrientation(sp.bodies[0], physicsClientId=cid)[0][:2]
        assert body_xy == pytest.approx(tuple(sp.positions()[0]))
    finally:
        p.disconnect(cid)


def test_a_triggered_person_waits_for_the_robot_then_the_delay():
    import pybullet as p

    bob = Person("bob", ((2.0, 2.0), (2.0, 0.5)), speed=1.0, delay=1.0, trigger=1.5)
    sp, cid = _people([bob], robot=(0.0, 2.0), seconds=3.0)
    try:
        assert sp.positions()[0] == pytest.approx([2.0, 2.0])  # the robot is 2 m away
        for _ in range(90):  # the robot comes within 1.5 m: 1 s delay, then 0.5 s of walking
            sp.step(1 / 60, (0.8, 2.0), 0.178)
        assert sp.positions()[0] == pytest.approx([2.0, 1.5], abs=0.03)
    finally:
        p.disconnect(cid)


def test_a_person_gives_way_to_the_robot_then_turns_round():
    """Walking straight at a robot standing in the way, a person stops YIELD_GAP short of
    its footprint, waits PATIENCE seconds and walks back; with the robot gone they walk on."""
    import pybullet as p

    cy = Person("cy", ((0.5, 1.0), (4.0, 1.0)), speed=1.0, radius=0.2)
    gap_at = 2.5 - 0.178 - YIELD_GAP - 0.2  # where the person stops [m]
    sp, cid = _people([cy], robot=(2.5, 1.0), seconds=(gap_at - 0.5) + PATIENCE - 0.1)
    try:
        gap = float(sp.gaps(2.5, 1.0, 0.178)[0])
        assert YIELD_GAP <= gap <= YIELD_GAP + 0.02  # a step (1.7 cm) short of coming closer
        for _ in range(round(1.1 * 60)):  # patience spent: 1 s walking back
            sp.step(1 / 60, (2.5, 1.0), 0.178)
        assert sp.walks[0].direction == -1 and sp.positions()[0][0] == pytest.approx(gap_at - 1.0, abs=0.05)
    finally:
        p.disconnect(cid)
    sp, cid = _people([cy], robot=(2.5, 1.0), seconds=gap_at)
    try:
        for _ in range(60):  # the robot moves away: on they walk
            sp.step(1 / 60, (2.5, 3.0), 0.178)
        assert sp.walks[0].direction == 1 and sp.positions()[0][0] > gap_at + 0.9
    finally:
        p.disconnect(cid)


def test_the_bumper_stops_the_base_at_a_person_it_drives_into(tmp_path, sim_section):
    path = _world_file(tmp_path, "people:\n  - {name: dee, waypoints: [[2.0, 2.0], [2.0, 3.5]], trigger: 0.01}\n")
    robot = build(sim_section(f"world: {path}\nphysics_hz: 60\n"), profile={}, seed=1, options={})
    try:
        for _ in range(100):
            robot.base.set_velocity(0.3, 0.0)
            robot.spin(0.05)
        st = robot.base.state()
        assert st.faults == {"bumper_centre"} and st.v == 0.0
        assert robot.truth.base_pose().x == pytest.approx(2.0 - 0.2 - 0.178, abs=0.03)
        assert [c.body for c in robot.core.contacts] == ["dee"]
    finally:
        robot.close()


# --------------------------------------------------------------------------- crowd and clutter


def test_the_crowd_walks_clear_loops_and_is_reproducible():
    w = load_world("lab", seed=9, randomize=True)
    cfg = FaultConfig(crowd=Crowd(count=3, waypoints=4))
    obstacles, people = world_extras(w, cfg, 9, 0.178)
    assert obstacles == () and [pe.name for pe in people] == ["crowd_1", "crowd_2", "crowd_3"]
    assert world_extras(w, cfg, 9, 0.178)[1] == people and world_extras(w, cfg, 10, 0.178)[1] != people
    free = _FreeSpace(w)
    for pe in people:
        assert len(pe.waypoints) == 4 and 0.3 <= pe.speed <= 1.2 and 0.15 <= pe.radius <= 0.25
        assert math.hypot(pe.waypoints[0][0] - w.start.x, pe.waypoints[0][1] - w.start.y) >= 1.2
        loop = list(pe.waypoints) + [pe.waypoints[0]]
        assert all(free.segment_clear(a, b, pe.radius + 0.05) for a, b in itertools.pairwise(loop))


def test_clutter_boxes_are_unmapped_near_the_routes_and_leave_a_way_through():
    w = load_world("lab", seed=6, randomize=True)  # the small lab has room for all three at this seed
    obstacles, people = world_extras(w, FaultConfig(clutter=Clutter(count=3)), 6, 0.178)
    assert people == () and len(obstacles) == 3
    assert all(o.unmapped and o.name.startswith("clutter_") for o in obstacles)
    places = _places(w, _FreeSpace(w))  # the places the boxes were kept clear of
    cluttered = replace(w, obstacles=w.obstacles + obstacles)
    free = _FreeSpace(cluttered)
    assert all(min(math.hypot(o.pose[0] - q[0], o.pose[1] - q[1]) for q in places) >= 0.8 for o in obstacles)
    half = (2 * 0.178 + 0.3) / 2
    assert _connected(free.dist >= half, [free.cell(*q) for q in places if free.clearance(*q) >= half])
    # the map the robot is given does not hold them
    assert all(_cell(cluttered.occupancy(0.05), o.pose[0], o.pose[1]) == 0 for o in obstacles)


def test_world_faults_draw_from_their_own_streams(sim_section):
    """Switching the crowd on leaves everything the seed drew before (start, items,
    sensor noise) as it was."""
    def first_scan(extra: str) -> tuple[Pose2D, np.ndarray]:
        r = build(sim_section(f"world: lab\nphysics_hz: 60\nrandomize: true\n{extra}"), profile={}, seed=5, options={})
        try:
            return r.truth.base_pose(), r.lidar.scan().ranges
        finally:
            r.close()

    pose0, scan0 = first_scan("")
    pose1, scan1 = first_scan("faults: {crowd: {count: 1}}\n")
    assert pose0 == pose1
    # the same noise draws: only the beams a person blocks differ
    assert np.mean(scan0 == scan1) > 0.8


# --------------------------------------------------------------------------- ground truth


def test_the_truth_log_records_clearance_people_and_contacts(tmp_path, sim_section):
    path = _world_file(tmp_path, "people:\n  - {name: eve, waypoints: [[1.0, 3.5], [5.0, 3.5]], speed: 1.0}\n")
    # a relative sidecar path is taken from the config file's folder
    sec = load_yaml_text(f"world: {path}\nphysics_hz: 60\ntruth_log: truth/{{seed}}.jsonl\n", str(tmp_path / "run.yaml"))
    robot = build(sec, profile={}, seed=42, options={})
    try:
        for _ in range(120):
            robot.base.set_velocity(0.4, 0.0)
            robot.spin(0.05)
    finally:
        robot.close()
    recs = [json.loads(ln) for ln in (tmp_path / "truth" / "42.jsonl").read_text().splitlines()]
    assert recs[0]["event"] == "truth_start" and recs[0]["seed"] == 42
    assert {o["name"]: o["unmapped"] for o in recs[0]["obstacles"]} == {"known": False, "parcel": True}
    ticks = [r for r in recs if r["event"] == "truth"]
    assert len(ticks) == 120 and ticks[0]["t"] == pytest.approx(0.05)
    # at the start: 1.0 m from the west wall is the nearest static part
    assert ticks[0]["clearance"] == pytest.approx(1.0 - 0.178, abs=0.03)
    assert ticks[0]["gaps"][0] == pytest.approx(math.hypot(ticks[0]["people"][0][0] - 1.0, 1.5) - 0.2 - 0.178,
                                                abs=0.02)
    contacts = [r for r in recs if r["event"] == "contact"]
    assert [(c["part"], c["body"]) for c in contacts] == [("base", "parcel")]
    end = recs[-1]
    assert end["event"] == "truth_end" and end["ticks"] == 120 and end["contacts"] == 1
    assert end["min_clearance"] == pytest.approx(0.0, abs=0.03) and end["nearest"] == "parcel"
    assert set(end["min_gap"]) == {"eve"}


def test_an_unknown_field_in_the_truth_log_name_is_a_located_error(sim_section):
    with pytest.raises(InputError, match=r"config.yaml:1:12: sim.truth_log: 'x_\{run\}.jsonl': only \{seed\}"):
        build(sim_section("truth_log: x_{run}.jsonl\n"), profile={}, seed=1, options={})


@pytest.mark.parametrize("robot_x", [2.6, 2.75])
def test_a_cornered_person_walks_round_the_robot(robot_x):
    """A robot standing by a waypoint where both legs of the loop pass it: the person
    waits, turns round, is blocked again at once (robot at 2.6, 0.22 m from them) or
    after a few steps back and forth (2.75), and walks round the robot (never closer to
    it than where they stood, out to YIELD_GAP from it, on the side the static geometry
    leaves free) on to the next waypoint,
    instead of standing there for ever (the crowd campaigns' 90 s timeouts)."""
    import pybullet as p

    robot = (robot_x, 2.0)
    w_pt, x_pt, y_pt = (2.0, 2.0), (4.0, 2.5), (4.0, 1.5)
    for clear, side in ((None, "south"), (lambda x, y, r: y - r > 1.75, "north")):
        cy = Person("cy", (w_pt, x_pt, y_pt), speed=1.0, radius=0.2)
        cid = p.connect(p.DIRECT)
        try:
            sp = SimPeople([cy], cid)
            start_gap = min(float(sp.gaps(*robot, 0.178)[0]), YIELD_GAP)
            gaps, path = [], []
            for _ in range(round((2 * PATIENCE + 4.0) * 60)):
                sp.step(1 / 60, robot, 0.178, clear)
                gaps.append(float(sp.gaps(*robot, 0.178)[0]))
                path.append(tuple(sp.positions()[0]))
            assert min(gaps) >= start_gap - 0.02  # never closer than where they stood (a step)
            assert sp.walks[0].direction == -1 and not sp.walks[0].rounding
            # past the robot, on their way from y_pt back round the loop
            assert math.hypot(path[-1][0] - w_pt[0], path[-1][1] - w_pt[1]) > 1.0
            ys = [q[1] for q in path if abs(q[0] - robot[0]) < 0.2]
            assert ys and (max(ys) < robot[1] if side == "south" else min(ys) > robot[1])
            # passing beside it no nearer than YIELD_GAP (stepping out from where the robot
            # came up to them: an item held out reaches 0.29 m past the LoCoBot's footprint)
            beside = [g for g, q in zip(gaps, path) if abs(q[0] - robot[0]) < 0.2]
            assert min(beside) >= YIELD_GAP - 0.02
        finally:
            p.disconnect(cid)
    # the old rule alone: a person kept waiting both ways stands there
    cy = Person("cy", (w_pt, x_pt, y_pt), speed=1.0, radius=0.2)
    sp, cid = _people([cy], robot=(2.6, 2.0), seconds=PATIENCE * 0.9)
    try:
        assert sp.positions()[0] == pytest.approx(w_pt) and sp.walks[0].waiting > 0.0
    finally:
        p.disconnect(cid)
