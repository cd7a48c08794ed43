"""The LoCoBot's pan/tilt head in the sim: goals reach the commanded pose, limits are
refused, cancel holds, and the camera's pose follows the head (a marker seen from two head
poses lands at the same map position, at its true one)."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from mmexec.drivers.interfaces import GoalState
from mmexec.sim.backend import build

MARKER = 7
MARKER_SIZE = 0.1  # m, tests/sim/data/bench.yaml item 'big'


@pytest.fixture(scope="module")
def robot(sim_section, bench_world):
    sec = sim_section(f"robot: locobot_wx250s\nworld: {bench_world}\n"
                      "camera: {width: 640, height: 480, tilt: 0.35}\n"
                      "odometry_noise: {linear: 0.0, angular: 0.0}\n")
    r = build(sec, profile={}, seed=0, options={})
    r.spin(0.5)  # let items settle
    yield r
    r.close()


def run(robot, goal, limit: float = 5.0) -> None:
    t_end = robot.clock.now() + limit
    while not goal.done():
        assert robot.clock.now() < t_end, f"{goal} not done after {limit} s"
        robot.spin(0.05)


def point(robot, pan: float, tilt: float) -> None:
    goal = robot.head.point(pan, tilt)
    run(robot, goal)
    assert goal.state is GoalState.SUCCEEDED, goal.reason


def marker_in_map(frame) -> np.ndarray:
    """Centre of marker MARKER in map from one frame (ArUco corners + IPPE)."""
    gray = cv2.cvtColor(frame.rgb, cv2.COLOR_RGB2GRAY)
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    det = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50), params)
    corners, ids, _ = det.detectMarkers(gray)
    assert ids is not None and MARKER in np.ravel(ids), "marker not seen"
    c = corners[list(np.ravel(ids)).index(MARKER)].reshape(4, 2)
    s = MARKER_SIZE
    obj = np.array([[-s / 2, s / 2, 0], [s / 2, s / 2, 0], [s / 2, -s / 2, 0], [-s / 2, -s / 2, 0]])
    ok, _rvec, tvec = cv2.solvePnP(obj, c, frame.intrinsics.matrix(), None, flags=cv2.SOLVEPNP_IPPE_SQUARE)
    assert ok
    return (frame.T_map_base @ frame.T_base_camera @ np.append(tvec.ravel(), 1.0))[:3]


def test_head_starts_at_the_configured_pose_which_is_its_home(robot):
    st = robot.head.state()
    assert (st.pan, st.tilt) == pytest.approx((0.0, 0.35), abs=1e-6)
    assert robot.head.home == (0.0, 0.35)
    assert robot.head.joint_names == ("pan", "tilt")
    assert [lim.upper for lim in robot.head.limits] == pytest.approx([math.pi / 2, 1.309])


def test_commanded_pose_is_reached(robot):
    for pan, tilt in ((0.8, -0.3), (-1.2, 0.9), (0.0, 0.35)):
        point(robot, pan, tilt)
        st = robot.head.state()
        assert st.pan == pytest.approx(pan, abs=robot.head.tolerance)
        assert st.tilt == pytest.approx(tilt, abs=robot.head.tolerance)


def test_targets_outside_the_limits_are_refused_and_nothing_moves(robot):
    point(robot, 0.2, 0.2)
    for pan, tilt, joint in ((2.0, 0.0, "pan"), (0.0, 1.4, "tilt"), (0.0, math.nan, "tilt")):
        goal = robot.head.point(pan, tilt)
        assert goal.state is GoalState.FAILED and goal.reason.startswith(f"{joint} = ")
    robot.spin(0.5)
    st = robot.head.state()
    assert (st.pan, st.tilt) == pytest.approx((0.2, 0.2), abs=robot.head.tolerance)


def test_cancel_holds_where_the_head_is(robot):
    point(robot, -1.0, 0.0)
    goal = robot.head.point(1.0, 0.0)
    robot.spin(0.25)  # part way: pi rad/s over 2 rad
    goal.cancel()
    assert goal.state is GoalState.CANCELLED
    held = robot.head.state().pan
    assert -0.9 < held < 0.9
    robot.spin(1.0)
    assert robot.head.state().pan == pytest.approx(held, abs=0.03)


def test_frames_carry_the_camera_pose_at_capture_while_the_head_moves(robot):
    point(robot, -0.5, 0.1)
    goal = robot.head.point(0.5, 0.5)
    robot.spin(0.15)
    frame = robot.camera.frame()
    st = robot.head.state()
    assert not goal.done() and -0.5 < st.pan < 0.5
    expected = robot.head.kinematics.T_root_optical(st.pan, st.tilt)
    assert np.allclose(frame.T_base_camera, expected, atol=1e-4)
    run(robot, goal)


def test_a_marker_lands_at_one_map_position_from_two_head_poses(robot):
    # the marker box is 1.2 m ahead of the base (tests/sim/data/bench.yaml); two quite
    # different head poses see it off-centre on opposite sides
    seen = []
    for pan, tilt in ((0.3, 0.2), (-0.25, -0.15)):
        point(robot, pan, tilt)
        seen.append(marker_in_map(robot.camera.frame()))
    assert np.linalg.norm(seen[0] - seen[1]) < 0.02, seen  # a fixed pose would put them ~0.5 m apart
    face = robot.truth.item_pose("big")[:3, 3] - np.array([0.07, 0.0, 0.0])  # the face towards the robot
    for p in seen:
        assert np.linalg.norm(p[:2] - face[:2]) < 0.02, (p, face)
    # and had the pose been taken as fixed (the head's start pose), the two would differ
    start = robot.head.kinematics.T_root_optical(0.0, 0.35)
    assert not np.allclose(robot.camera.pose_in_base(), start, atol=0.05)


def test_look_at_centres_a_point(robot):
    target = robot.truth.item_pose("big")[:3, 3] - np.array([0.07, 0.0, 0.0])
    in_base = np.linalg.inv(robot.core.base_T()) @ np.append(target, 1.0)
    goal = robot.head.look_at(in_base[:3])
    run(robot, goal)
    assert goal.state is GoalState.SUCCEEDED, goal.reason
    T_map_opt = robot.core.base_T() @ robot.camera.pose_in_base()
    p = np.linalg.inv(T_map_opt) @ np.append(target, 1.0)
    assert math.hypot(p[0], p[1]) / p[2] < 0.03  # within ~2 degrees of the optical axis


def test_a_robot_without_a_head_has_none(sim_section, bench_world):
    r = build(sim_section(f"robot: ur5e_robotiq\nworld: {bench_world}\ncamera: {{width: 64, height: 48}}\n"),
              profile={}, seed=0, options={})
    try:
        assert r.head is None
        r.safe_stop()
    finally:
        r.close()


class ArucoBoxes:
    """An ObjectDetector for the sim's marker boxes: label ``marker<id>``, the marker's
    bounding box, confidence 0.9 (detection on the rendered image)."""

    classes = (f"marker{MARKER}",)

    def detect(self, rgb: np.ndarray) -> list:
        from mmexec.skills.perception.detector import Detection

        det = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50))
        corners, ids, _ = det.detectMarkers(cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY))
        out = []
        for c, i in zip(corners, np.ravel(ids) if ids is not None else []):
            x, y, w, h = cv2.boundingRect(c.reshape(4, 2).astype(np.float32))
            out.append(Detection(f"marker{int(i)}", 0.9, (int(x), int(y), int(w), int(h))))
        return out


@pytest.mark.slow
def test_the_scan_skill_on_the_sim_head_finds_the_box_where_it_is(robot):
    from mmexec.skills.base import SkillContext, SkillStatus, run_skill
    from mmexec.skills.perception.scan import WORLD_OBJECT_DETECTOR, WORLD_SCAN, scan

    point(robot, *robot.head.home)
    robot.profile = {"scan": {"head_poses": [[0.35, 0.1], [0.1, 0.1], [-0.1, 0.1], [-0.35, 0.1]]}}
    ctx = SkillContext.for_robot(robot)
    ctx.world[WORLD_OBJECT_DETECTOR] = ArucoBoxes()
    run = run_skill(scan.spec, ctx, {"label": f"marker{MARKER}", "size": [0.14, 0.14, 0.14]},
                    step=lambda: robot.spin(0.05))
    assert run.status is SkillStatus.SUCCESS, run.failure
    obj = run.outputs["object"]
    assert run.outputs["views"] == 4 and run.outputs["predictions"] == 8
    assert obj["seen"] >= 4 and obj["spread"] < 0.02  # seen from several head poses, at one place
    truth = robot.truth.item_pose("big")[:3, 3]
    # the marker's box covers the face only: its centre of mass, completed with the size
    assert np.linalg.norm(np.array(obj["position"])[:2] - truth[:2]) < 0.03, (obj, truth)
    views = {p.view for p in ctx.world[WORLD_SCAN].objects[0].predictions}
    assert len(views) >= 2
    st = robot.head.state()
    assert (st.pan, st.tilt) == pytest.approx(robot.head.home, abs=robot.head.tolerance)


@pytest.mark.slow
def test_without_a_head_the_scan_moves_the_wrist_camera_through_the_arm(sim_section, bench_world, repo_root):
    """The UR5e (wrist camera, no head): four named arm poses from the profile, planned
    and executed like any named move; the box found where it is."""
    from mmexec.executive.config import load_config
    from mmexec.skills.base import SkillContext, SkillStatus, run_skill
    from mmexec.skills.perception.scan import WORLD_OBJECT_DETECTOR, scan

    profile = dict(load_config(repo_root / "config" / "ur5e_sim.yaml").config.profile)
    look = list(profile["named_poses"]["look"])
    poses = dict(profile["named_poses"])
    for name, pan in (("scan_l2", 0.4), ("scan_l1", 0.15), ("scan_r1", -0.15), ("scan_r2", -0.4)):
        poses[name] = [pan, *look[1:]]
    profile["named_poses"] = poses
    profile["scan"] = {"arm_poses": ["scan_l2", "scan_l1", "scan_r1", "scan_r2"]}
    r = build(sim_section(f"robot: ur5e_robotiq\nworld: {bench_world}\nphysics_hz: 120\n"
                          "camera: {width: 512, height: 384}\nodometry_noise: {linear: 0.0, angular: 0.0}\n"),
              profile=profile, seed=0, options={})
    try:
        assert r.head is None
        ctx = SkillContext.for_robot(r)
        ctx.world[WORLD_OBJECT_DETECTOR] = ArucoBoxes()
        run = run_skill(scan.spec, ctx, {"label": f"marker{MARKER}", "size": [0.14, 0.14, 0.14]},
                        step=lambda: r.spin(0.05))
        assert run.status is SkillStatus.SUCCESS, run.failure
        obj = run.outputs["object"]
        assert run.outputs["views"] == 4 and obj["seen"] >= 2
        assert r.arm.state().positions[0] == pytest.approx(-0.4, abs=0.02)  # the arm stays at the last pose
        truth = r.truth.item_pose("big")[:3, 3]
        assert np.linalg.norm(np.array(obj["position"])[:2] - truth[:2]) < 0.03, (obj, truth)
    finally:
        r.close()


def _search_robot(sim_section, bench_world, head_pans):
    r = build(sim_section(f"robot: locobot_wx250s\nworld: {bench_world}\n"
                          "camera: {width: 512, height: 384, tilt: 0.1}\n"
                          "odometry_noise: {linear: 0.0, angular: 0.0}\n"),
              profile={"camera": {"marker_length": MARKER_SIZE}, "search": {"head_pans": head_pans}},
              seed=0, options={})
    from mmexec.drivers.interfaces import Pose2D

    r.core.place_base(Pose2D(1.0, 1.0, 0.9))  # the marker 0.9 rad to the right: outside the view
    r.base.reset_estimate(Pose2D(1.0, 1.0, 0.9))
    return r


@pytest.mark.parametrize("head_pans", [[], [0.0, -0.9]])
def test_search_looks_with_the_head_before_turning_the_base(sim_section, bench_world, head_pans):
    from mmexec.skills.base import SkillContext, SkillStatus, run_skill
    from mmexec.skills.search import search

    r = _search_robot(sim_section, bench_world, head_pans)
    try:
        run = run_skill(search.spec, SkillContext.for_robot(r), {"marker": MARKER, "step": 30.0},
                        step=lambda: r.spin(0.05))
        assert run.status is SkillStatus.SUCCESS, run.failure
        face = r.truth.item_pose("big")[:3, 3] - np.array([0.07, 0.0, 0.0])
        assert np.linalg.norm(np.array(run.outputs["pose"][:2]) - face[:2]) < 0.02
        turned = abs(r.truth.base_pose().theta - 0.9)
        st = r.head.state()
        assert (st.pan, st.tilt) == pytest.approx(r.head.home, abs=r.head.tolerance)  # back home either way
        if head_pans:
            assert run.outputs["views"] == 2 and turned < 1e-6 and r.head.moves == 3  # -0.9, then home
        else:
            assert run.outputs["views"] >= 2 and turned > 0.4 and r.head.moves == 0   # the base had to turn
    finally:
        r.close()
