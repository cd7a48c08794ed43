from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from mmexec.drivers.interfaces import SceneBox
from mmexec.skills.manipulation.grasp import grasp_poses, place_poses, tool_rotation_in_marker
from mmexec.skills.manipulation.kinematics import wx250s
from mmexec.skills.manipulation.planner import ArmPlanner, PlannerConfig, time_parametrize
from mmexec.skills.manipulation.scene import ArmModel, PlanningScene

HOME = (0.0, -0.4, 0.6, 0.0, 1.2, 0.0)


def _box(name, c, size):
    T = np.eye(4)
    T[:3, 3] = c
    return SceneBox(name, T, size)


@pytest.fixture(scope="module")
def scene():
    sc = PlanningScene(ArmModel.from_sim_model("locobot_wx250s"))
    yield sc
    sc.close()


def test_self_collision_and_static_boxes(scene):
    scene.set_static_boxes([])
    assert scene.is_valid(HOME)
    # arm leaning back into the camera tower
    assert not scene.is_valid((0.0, -1.1, 1.55, 0.0, 0.5, 0.0))
    assert ("robot/upper_arm_link", "robot/camera_tower_link") in scene.collisions((0.0, -1.1, 1.55, 0.0, 0.5, 0.0))
    # a box where the stretched-out arm is; boxes given in map with the base moved 1 m
    T_armbase_map = np.eye(4)
    T_armbase_map[0, 3] = -1.0
    scene.set_static_boxes([_box("wall", (1.4, 0.0, 0.35), (0.05, 1.0, 1.0))], T_armbase_map)
    assert scene.static_boxes == ["wall"]
    assert not scene.is_valid(np.zeros(6))
    assert scene.collisions(np.zeros(6))[0][1] == "wall"
    assert scene.is_valid(HOME)
    # outside the joint limits is invalid too
    assert not scene.is_valid((0.0, 2.5, 0.0, 0.0, 0.0, 0.0))
    scene.set_static_boxes([])
    assert scene.is_valid(np.zeros(6))


def test_item_add_attach_detach_remove(scene):
    kin = wx250s()
    scene.set_static_boxes([_box("table", (0.35, 0.0, -0.05), (0.3, 0.6, 0.02))])
    q_grasp = kin.ik(_tool_at(0.35, 0.0, 0.05), HOME)
    assert q_grasp is not None
    # the item sits between the fingers at the grasp
    T_item = kin.fk(q_grasp)
    scene.add_item("box7", (0.03, 0.09, 0.04), T_item)  # wider than the open fingers
    assert not scene.is_valid(q_grasp)  # fingers inside a free item: collision
    scene.attach_item("box7", q_grasp)
    assert scene.items["box7"].attached
    assert scene.is_valid(q_grasp)      # held: the gripper may touch it
    # carried item hits the table when the tool goes down to it
    q_low = kin.ik(_tool_at(0.35, 0.0, -0.03), q_grasp)
    assert q_low is not None
    assert not scene.is_valid(q_low)
    assert any("box7" in pair for pair in scene.collisions(q_low))
    q_up = kin.ik(_tool_at(0.30, 0.0, 0.20), q_grasp)
    assert q_up is not None and scene.is_valid(q_up)
    scene.detach_item("box7", q_grasp)
    assert not scene.items["box7"].attached
    assert scene.is_valid(q_grasp)      # released where it was: gripper still allowed
    assert np.allclose(scene.items["box7"].T, T_item, atol=1e-6)
    assert scene.is_valid(q_up)
    scene.remove_item("box7")
    assert "box7" not in scene.items
    with pytest.raises(KeyError):
        scene.remove_item("box7")
    scene.set_static_boxes([])



@pytest.mark.parametrize("sink,ok", [(0.004, True), (0.03, False)])
def test_held_item_modelled_into_its_board_is_lifted_out(scene, sink, ok):
    """A box grasped on a board but modelled ``sink`` lower than it is (marker estimate
    error): a few mm are estimate error, moved out along the contact normal (up) so the
    retract can start; 3 cm is a real collision and is left for the planner to report."""
    kin = wx250s()
    q_grasp = kin.ik(_tool_at(0.35, 0.0, 0.10), HOME)
    assert q_grasp is not None
    T_item = kin.fk(q_grasp)
    # the board's top is 0.02 below the item centre: a 0.04 m tall item rests on it
    scene.set_static_boxes([_box("board", (0.35, 0.0, 0.10 - 0.02 - 0.01), (0.3, 0.6, 0.02))])
    T_model = T_item.copy()
    T_model[2, 3] -= sink
    scene.add_item("box8", (0.03, 0.03, 0.04), T_model)
    scene.attach_item("box8", q_grasp)
    try:
        assert not scene.is_valid(q_grasp)
        if ok:
            shift = scene.clear_attached_from_static("box8", q_grasp)
            assert shift == pytest.approx(sink + 5e-4, abs=2e-4)
            assert scene.is_valid(q_grasp)
            T_now = scene.tool_pose(q_grasp) @ scene.items["box8"].T
            assert T_now[:3, 3] == pytest.approx(T_model[:3, 3] + [0.0, 0.0, shift], abs=1e-6)
        else:
            with pytest.raises(ValueError, match="mm into board"):
                scene.clear_attached_from_static("box8", q_grasp)
    finally:
        scene.remove_item("box8")
        scene.set_static_boxes([])

def _tool_at(x, y, z):
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


def test_plan_around_obstacle_and_failure_reasons(scene):
    kin = wx250s()
    scene.set_static_boxes([_box("post", (0.30, 0.0, 0.15), (0.06, 0.06, 0.40))])
    q_a = kin.ik(_tool_at(0.30, 0.20, 0.10), HOME, is_valid=scene.is_valid)
    q_b = kin.ik(_tool_at(0.30, -0.20, 0.10), HOME, is_valid=scene.is_valid)
    assert q_a is not None and q_b is not None
    planner = ArmPlanner(scene, kin, PlannerConfig(time_limit=2.0, attempts=3))
    r = planner.plan(q_a, q_b)
    assert r.success, r.reason
    assert r.path[0] == pytest.approx(tuple(q_a)) and r.path[-1] == pytest.approx(tuple(q_b))
    # every edge is collision-free at a fine resolution
    for a, b in zip(r.path, r.path[1:]):
        for s in np.linspace(0, 1, 60):
            assert scene.is_valid(np.asarray(a) + s * (np.asarray(b) - np.asarray(a)))
    tr = r.trajectory
    assert tr is not None and tr.positions[-1] == pytest.approx(tuple(q_b))
    _check_limits(tr, kin, q_a, 0.5)
    r2 = ArmPlanner(scene, kin, PlannerConfig(algorithm="rrtstar", time_limit=2.0)).plan(q_a, q_b)
    assert r2.success
    bad = planner.plan(q_a, (0.0, -1.1, 1.55, 0.0, 0.5, 0.0))
    assert not bad.success and bad.reason.startswith("goal in collision: robot/upper_arm_link")
    bad = planner.plan((0.0, -1.1, 1.55, 0.0, 0.5, 0.0), q_a)
    assert not bad.success and bad.reason.startswith("start in collision")
    r3 = planner.plan_to_pose(q_a, _tool_at(1.2, 0.0, 0.2))
    assert not r3.success and r3.reason == "no IK"
    # around the post but with (almost) no time: no plan, and the reason says so
    nope = planner.plan(q_a, q_b, PlannerConfig(time_limit=1e-5, attempts=2))
    assert not nope.success and nope.reason == "no plan within 1e-05 s x 2 attempts"
    assert nope.attempts == 2
    scene.set_static_boxes([])


def _check_limits(tr, kin, q0, scale):
    prev_t, prev_q = 0.0, np.asarray(q0)
    vmax = np.array([lim.velocity for lim in kin.limits]) * scale
    for t, q in zip(tr.times, tr.positions):
        v = (np.asarray(q) - prev_q) / (t - prev_t)
        assert np.all(np.abs(v) <= vmax + 1e-6)
        prev_t, prev_q = t, np.asarray(q)


def test_time_parametrization_respects_velocity_and_acceleration():
    kin = wx250s()
    path = [(0.0,) * 6, (1.0, -0.5, 0.2, 0.0, 0.0, 0.0), (1.0, 0.5, 0.2, 0.3, 0.0, 0.0)]
    tr = time_parametrize(kin.joint_names, path, kin.limits, velocity_scale=0.5, acceleration_scale=0.4, sample_period=0.01)
    ts = np.array((0.0,) + tr.times)
    qs = np.array((path[0],) + tr.positions)
    v = np.diff(qs, axis=0) / np.diff(ts)[:, None]
    assert np.abs(v).max() <= math.pi * 0.5 + 1e-6
    # acceleration from the sampled velocities (midpoint differences)
    tm = (ts[1:] + ts[:-1]) / 2
    a = np.diff(v, axis=0) / np.diff(tm)[:, None]
    assert np.abs(a).max() <= 5.0 * 0.4 * 1.05
    assert tr.positions[-1] == pytest.approx(path[-1])
    assert any(np.allclose(p, path[1]) for p in tr.positions)  # stops at the corner
    # 1 rad on the waist at 2 rad/s^2: at least 2 * sqrt(1 / 2) s
    assert tr.duration > 2 * math.sqrt(1.0 / 2.0)



def _sampled_limits(path, tr):
    ts = np.array((0.0,) + tr.times)
    qs = np.array((path[0],) + tr.positions)
    v = np.diff(qs, axis=0) / np.diff(ts)[:, None]
    tm = (ts[1:] + ts[:-1]) / 2
    a = np.diff(v, axis=0) / np.diff(tm)[:, None]
    return np.abs(v).max(axis=0), np.abs(a).max(axis=0)


def test_dense_nearly_straight_path_is_run_through_not_stopped_at_each_waypoint():
    """A Cartesian line's IK waypoints (here 20 points along a gently curving joint-space
    arc): one speed profile over the whole path, not 20 rest-to-rest moves, within the
    velocity and acceleration limits, through every waypoint."""
    kin = wx250s()
    s = np.linspace(0.0, 1.0, 21)
    path = [(0.6 * x, -0.3 * x + 0.02 * math.sin(math.pi * x), 0.25 * x, 0.0, 0.1 * x, 0.0) for x in s]
    tr = time_parametrize(kin.joint_names, path, kin.limits, velocity_scale=0.5, acceleration_scale=0.5,
                          sample_period=0.02)
    def rest_to_rest(a, b):
        return time_parametrize(kin.joint_names, [a, b], kin.limits, velocity_scale=0.5, acceleration_scale=0.5,
                                sample_period=0.02).duration

    stop_and_go = sum(rest_to_rest(a, b) for a, b in itertools.pairwise(path))
    one_move = rest_to_rest(path[0], path[-1])  # the chord: a lower bound
    assert one_move < tr.duration < 1.5 * one_move
    assert tr.duration < 0.4 * stop_and_go
    vmax = np.array([lim.velocity for lim in kin.limits]) * 0.5
    amax = np.array([lim.acceleration if math.isfinite(lim.acceleration) else 2.0 for lim in kin.limits]) * 0.5
    v, a = _sampled_limits(path, tr)
    assert np.all(v <= vmax + 1e-6)
    assert np.all(a <= amax * 1.1 + 1e-6)
    for q in path[1:]:
        assert any(np.allclose(p, q) for p in tr.positions)
    assert tr.positions[-1] == pytest.approx(path[-1])
    # ends at rest: the last step is short
    assert np.abs(np.array(tr.positions[-1]) - np.array(tr.positions[-2])).max() < 0.01

def test_cartesian_line(scene):
    kin = wx250s()
    scene.set_static_boxes([])
    q0 = kin.ik(_tool_at(0.30, 0.0, 0.15), HOME)
    planner = ArmPlanner(scene, kin)
    r = planner.cartesian_path(q0, _tool_at(0.40, 0.0, 0.15), step=0.01)
    assert r.success, r.reason
    for q in r.path:
        p = kin.fk(q)[:3, 3]
        assert abs(p[1]) < 2e-3 and abs(p[2] - 0.15) < 2e-3
    scene.set_static_boxes([_box("wall", (0.36, 0.0, 0.15), (0.01, 0.4, 0.4))])
    r = planner.cartesian_path(q0, _tool_at(0.40, 0.0, 0.15), step=0.01)
    assert not r.success and "straight line in collision" in r.reason and "wall" in r.reason
    scene.set_static_boxes([])


def test_grasp_and_place_poses_follow_the_seed():
    T_map_marker = np.eye(4)
    # marker on a box face looking back at the robot (-x in map), y up
    T_map_marker[:3, :3] = np.array([[0, 0, -1], [-1, 0, 0], [0, 1, 0]], dtype=float)
    T_map_marker[:3, 3] = (2.0, 1.0, 0.3)
    g = grasp_poses(T_map_marker, approach_axis=0)
    assert g.pre_grasp[:3, 3] == pytest.approx((1.9, 1.0, 0.3))        # 10 cm out along z_marker
    assert g.grasp[:3, 3] == pytest.approx((2.0, 1.0, 0.3))
    assert g.retract[:3, 3] == pytest.approx((1.9, 1.0, 0.2))          # (0, -0.1, 0.1): out and down
    assert g.grasp[:3, 0] == pytest.approx((1.0, 0.0, 0.0))            # WX250s approach (x) into the face
    assert g.grasp[:3, 2] == pytest.approx((0.0, 0.0, 1.0))            # gripper upright
    up = grasp_poses(T_map_marker, approach_axis=0, retract=(0.0, 0.10, 0.10), grasp_depth=0.02)
    assert up.retract[:3, 3] == pytest.approx((1.9, 1.0, 0.4))
    assert up.grasp[:3, 3] == pytest.approx((2.02, 1.0, 0.3))
    u = grasp_poses(T_map_marker, approach_axis=2)
    assert u.grasp[:3, 2] == pytest.approx((1.0, 0.0, 0.0))            # UR TCP approaches along z
    for ax in (0, 2):
        R = tool_rotation_in_marker(ax)
        assert np.allclose(R @ R.T, np.eye(3)) and np.linalg.det(R) == pytest.approx(1.0)
    pl = place_poses(T_map_marker, approach_axis=0)
    assert pl.place[:3, 3] == pytest.approx((2.0, 1.0, 0.3))
    assert pl.retract[:3, 3] == pytest.approx((1.9, 1.0, 0.3))
    with pytest.raises(ValueError):
        tool_rotation_in_marker(1)
