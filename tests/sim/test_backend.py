"""Backend behaviour: limits, watchdog, bumper, grasping, determinism, faults, config errors."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mmexec.config.yamlload import InputError
from mmexec.drivers.interfaces import GoalState, GraspState, JointTrajectory, Pose2D
from mmexec.sim.backend import SimError, build


@pytest.fixture(scope="module")
def robot(sim_section, bench_world):
    r = build(sim_section(f"world: {bench_world}\nphysics_hz: 120\n"), profile={"poses": {}}, seed=3, options={})
    yield r
    r.close()


def _run(r, goal, limit=10.0):
    t0 = r.clock.now()
    while not goal.done() and r.clock.now() - t0 < limit:
        r.spin(0.05)
    return goal


def test_spin_steps_whole_substeps(robot):
    t0 = robot.clock.now()
    robot.spin(0.1)
    assert robot.clock.now() - t0 == pytest.approx(0.1)
    with pytest.raises(ValueError, match="whole number"):
        robot.spin(0.013)


def test_trajectory_outside_range_fails_at_once_naming_joint(robot):
    before = robot.arm.state().positions
    names = robot.arm.joint_names
    bad = list(before)
    bad[2] = 2.5  # elbow upper limit 1.6057
    g = robot.arm.follow(JointTrajectory(names, (3.0,), (tuple(bad),)))
    assert g.state is GoalState.FAILED and "joint elbow" in g.reason and "outside limits" in g.reason
    fast = list(before)
    fast[0] += 1.0
    g = robot.arm.follow(JointTrajectory(names, (0.1,), (tuple(fast),)))  # 10 rad/s > pi
    assert g.state is GoalState.FAILED and "joint waist" in g.reason and "velocity" in g.reason
    robot.spin(0.2)
    assert np.allclose(robot.arm.state().positions, before, atol=2e-3)


def test_arm_reaches_and_cancel_decelerates(robot):
    g = _run(robot, robot.arm.move_to([0.3, -0.5, 0.5, 0.0, 0.3, 0.0]))
    assert g.state is GoalState.SUCCEEDED
    assert np.allclose(robot.arm.state().positions, [0.3, -0.5, 0.5, 0.0, 0.3, 0.0], atol=0.01)
    g = robot.arm.move_to([-0.3, -0.5, 0.5, 0.0, 0.3, 0.0], speed_scale=0.3)
    robot.spin(0.5)
    g.cancel()
    assert g.state is GoalState.CANCELLING
    _run(robot, g)
    assert g.state is GoalState.CANCELLED
    q = robot.arm.state().positions[0]
    robot.spin(0.5)
    assert abs(robot.arm.state().positions[0] - q) < 0.01 and 0.3 > q > -0.3


def test_watchdog_stops_the_base(robot):
    robot.core.place_base(Pose2D(1.0, 1.0, 0.0))
    robot.base.reset_estimate(Pose2D(1.0, 1.0, 0.0))
    robot.base.set_velocity(0.3, 0.0)
    robot.spin(0.5)
    assert robot.base.state().v == pytest.approx(0.3)
    robot.spin(0.5)  # no new command: the 0.6 s watchdog brakes at 1 m/s^2
    assert robot.base.state().v == 0.0
    x = robot.truth.base_pose().x
    robot.spin(0.5)
    assert robot.truth.base_pose().x == x
    assert 1.1 < x < 1.3


def test_bumper_stops_at_wall(robot):
    robot.core.place_base(Pose2D(3.4, 1.0, 0.0))
    for _ in range(40):
        robot.base.set_velocity(0.5, 0.0)
        robot.spin(0.05)
    st = robot.base.state()
    assert "bumper_centre" in st.faults and st.v == 0.0
    x = robot.truth.base_pose().x
    assert 4.0 - 0.178 - 0.05 < x <= 4.0 - 0.178 + 1e-3  # body cylinder touching the east wall
    robot.base.set_velocity(-0.2, 0.0)
    robot.spin(0.3)
    assert robot.truth.base_pose().x < x and not robot.base.state().faults


def _grasp_setup(robot):
    """Tool point (arm zero pose) at the cube's centre, gripper open; teleported, so
    nothing sweeps through the cube on the way."""
    robot.base.stop()
    robot.spin(0.5)
    robot.gripper.set_width(0.074)
    robot.arm.set_positions([0.0] * 6)
    robot.core.place_base(Pose2D(1.0, 2.2, 0.0))
    robot.spin(0.05)


def test_grasp_holds_with_both_pads_and_lifts(robot):
    _grasp_setup(robot)
    assert np.allclose(robot.truth.item_pose("cube")[:3, 3], (1.5556, 2.2, 0.4638), atol=0.01), robot.truth.item_pose("cube")[:3, 3]
    z0 = robot.truth.item_pose("cube")[2, 3]
    g = _run(robot, robot.gripper.close(force=10.0))
    assert g.state is GoalState.SUCCEEDED
    st = g.result
    assert st.grasp is GraspState.CONTACT_CLOSING and st.holding
    assert st.width == pytest.approx(0.06, abs=0.005)
    assert robot.truth.held_item() == "cube"
    g = _run(robot, robot.arm.move_to([0.0, -0.3, 0.0, 0.0, 0.3, 0.0]))
    assert g.state is GoalState.SUCCEEDED
    robot.spin(0.5)
    assert robot.truth.item_pose("cube")[2, 3] > z0 + 0.05
    assert robot.gripper.state().grasp is GraspState.CONTACT_CLOSING
    g = _run(robot, robot.gripper.open())
    assert g.state is GoalState.SUCCEEDED and robot.truth.held_item() is None
    robot.spin(1.0)
    assert robot.truth.item_pose("cube")[2, 3] < z0 + 0.01  # fell back down


def test_closing_on_nothing_is_not_a_grasp(robot):
    robot.core.place_base(Pose2D(1.0, 1.6, 0.0))
    robot.arm.set_positions([0.0] * 6)
    robot.gripper.set_width(0.074)
    g = _run(robot, robot.gripper.close())
    assert g.result.grasp is GraspState.AT_POSITION and not g.result.holding
    assert g.result.width == pytest.approx(0.030, abs=1e-3)


def test_same_seed_same_trajectory(sim_section, bench_world):
    def run(seed):
        r = build(sim_section("world: lab\nrandomize: true\nphysics_hz: 60\n"
                              "odometry_noise: {linear: 0.05, angular: 0.05}\n"), profile={}, seed=seed, options={})
        out = []
        for i in range(30):
            r.base.set_velocity(0.4, 0.5 * math.sin(i / 5))
            r.spin(0.1)
            s = r.base.state().pose
            out.append((s.x, s.y, s.theta))
        start = r.world.start
        r.close()
        return np.array(out), start
    a, sa = run(11)
    b, sb = run(11)
    c, _sc = run(12)
    assert np.array_equal(a, b) and sa == sb
    assert not np.allclose(a, c)


def test_faults_fire(sim_section, bench_world):
    sec = sim_section(f"world: {bench_world}\nphysics_hz: 60\nfaults:\n  arm_fail_attempts: [1]\n"
                      "  camera_dropout: {intervals: [[0.0, 0.5]]}\n  lidar_dropout: {p: 1.0}\n"
                      "  nav_blocked: [cube]\n  grasp_slip: {after: 0.3}\n")
    r = build(sec, profile={}, seed=0, options={})
    try:
        assert r.camera.frame() is None and r.lidar.scan() is None
        g = _run(r, r.arm.move_to([0.2, -0.5, 0.5, 0.0, 0.3, 0.0]))
        assert g.state is GoalState.FAILED and "injected" in g.reason
        g = _run(r, r.arm.move_to([0.2, -0.5, 0.5, 0.0, 0.3, 0.0]))
        assert g.state is GoalState.SUCCEEDED
        r.spin(0.5)
        assert r.camera.frame() is not None
        # the approach area in front of 'cube' is blocked in the map and in physics
        T = r.world.item_poses["cube"]
        ahead = T[:3, 3] + 0.5 * T[:3, 0]
        g_ = r.occupancy
        assert g_.data[int((ahead[1] - g_.origin.y) / g_.resolution), int((ahead[0] - g_.origin.x) / g_.resolution)] == 100
        # slip: a grasped item drops 0.3 s later
        _grasp_setup(r)
        g = _run(r, r.gripper.close(force=10.0))
        assert g.result.holding
        r.spin(0.5)
        assert r.gripper.state().grasp is GraspState.DROPPED and r.truth.held_item() is None
        kinds = {k.split()[0] for _, k in r.truth.faults_fired()}
        assert kinds == {"arm_fail", "camera_dropout", "lidar_dropout", "grasp_slip"}
    finally:
        r.close()


def test_marker_bias_moves_printed_marker(sim_section, bench_world):
    import pybullet as p

    r = build(sim_section(f"world: {bench_world}\nfaults: {{marker_bias: {{big: [0.02, 0.01]}}}}\n"),
              profile={}, seed=0, options={})
    try:
        body = r.scene_handles.items["big"]
        link = p.getLinkState(body, 0, computeForwardKinematics=True, physicsClientId=r.cid)[4]
        T = r.truth.item_pose("big")
        rel = T[:3, :3].T @ (np.array(link) - T[:3, 3])
        assert rel[1] == pytest.approx(0.02, abs=1e-4) and rel[2] == pytest.approx(0.01, abs=1e-4)
    finally:
        r.close()


@pytest.mark.parametrize("text, msg", [
    ("robot: locobot\n", r"config.yaml:1:8: sim.robot: expected one of .*did you mean 'locobot_wx250s'"),
    ("physic_hz: 100\n", r"config.yaml:1:1: sim.physic_hz: unknown key; did you mean 'physics_hz'"),
    ("world: labb\n", r"config.yaml:1:8: unknown world 'labb'"),
    ("faults: {nav_blocked: [box_9]}\n", r"config.yaml:1:23: sim.faults.nav_blocked: no item 'box_9'"),
    ("camera: {near: 2.0, far: 1.0}\n", r"config.yaml:1:9: sim.camera: camera needs 0 < near < far"),
])
def test_bad_sim_sections(sim_section, text, msg):
    import re

    with pytest.raises(InputError) as e:
        build(sim_section(text), profile={}, seed=0, options={})
    assert re.search(msg, str(e.value).splitlines()[0]), str(e.value)


def test_gui_without_display_is_a_clear_error(monkeypatch, sim_section):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with pytest.raises(SimError, match="--gui: no display"):
        build(None, profile={}, seed=0, options={"gui": True})


def test_record_writes_a_gif(tmp_path, sim_section, bench_world):
    out = tmp_path / "run.gif"
    r = build(sim_section(f"world: {bench_world}\nphysics_hz: 60\n"), profile={}, seed=0, options={"record": out})
    r.recorder.size = (80, 60)
    r.recorder._proj = __import__("pybullet").computeProjectionMatrixFOV(60.0, 80 / 60, 0.05, 20.0, physicsClientId=r.cid)
    for _ in range(15):  # drive so that frames differ (GIF writers merge identical frames)
        r.base.set_velocity(0.0, 1.5)
        r.spin(0.1)
    r.close()
    import imageio.v2 as imageio

    frames = imageio.mimread(str(out))
    assert len(frames) == 3 and frames[0].shape[:2] == (60, 80)


def test_record_writes_an_mp4(tmp_path, sim_section, bench_world):
    import imageio.v2 as imageio
    import pybullet as p

    out = tmp_path / "sub" / "run.mp4"
    r = build(sim_section(f"world: {bench_world}\nphysics_hz: 60\n"), profile={}, seed=0, options={"record": out})
    r.recorder.size = (64, 48)
    r.recorder._proj = p.computeProjectionMatrixFOV(60.0, 64 / 48, 0.05, 20.0, physicsClientId=r.cid)
    for _ in range(20):
        r.base.set_velocity(0.0, 1.5)
        r.spin(0.1)
    r.close()
    frames = imageio.mimread(str(out), format="FFMPEG")
    assert len(frames) == 4 and frames[0].shape[:2] == (48, 64)
    assert float(np.abs(frames[0].astype(int) - frames[-1].astype(int)).mean()) > 1.0  # the view turned


@pytest.mark.parametrize("name, msg", [("x.avi", "must end in .mp4 or .gif"), ("afile/x.mp4", "cannot create the folder")])
def test_bad_record_path_is_a_sim_error_at_build(tmp_path, name, msg):
    (tmp_path / "afile").write_text("")
    with pytest.raises(SimError, match=msg):
        build(None, profile={}, seed=0, options={"record": tmp_path / name})


def test_one_pad_contact_is_not_a_grasp(sim_section):
    """The box is pressed against a fixed post: the +y pad touches the box, the -y pad only
    the post, so closing stops early without a grasp."""
    from pathlib import Path

    world = Path(__file__).parent / "data" / "onepad.yaml"
    r = build(sim_section(f"world: {world}\n"), profile={}, seed=0, options={})
    try:
        _grasp_setup(r)
        slim = r.scene_handles.items["slim"]
        g = r.gripper.close(force=5.0)
        touched: list[set[int]] = [set(), set()]
        while not g.done() and r.clock.now() < 30.0:
            r.spin(0.05)
            for pad, bodies in zip(touched, r.gripper._contacts()):
                pad |= bodies
        assert g.state is GoalState.SUCCEEDED
        st = g.result
        assert st.grasp is GraspState.AT_POSITION and not st.holding and r.truth.held_item() is None
        assert st.width > 0.035  # stopped on the box and the post, far from the 30 mm closed width
        assert [slim in t for t in touched].count(True) == 1  # only one pad ever touched the box
        assert r.scene_handles.static in touched[0] | touched[1]  # the other stopped on the post
        z0 = r.truth.item_pose("slim")[2, 3]
        g = _run(r, r.arm.move_to([0.0, -0.3, 0.0, 0.0, 0.3, 0.0]))
        r.spin(0.5)
        assert r.truth.item_pose("slim")[2, 3] < z0 + 0.01  # not lifted
    finally:
        r.close()
