"""DWA local planner: dynamic window, rollouts, admissibility, scoring, path following,
blocked path and stuck detection."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from mmexec.drivers.interfaces import OccupancyGrid, Pose2D
from mmexec.skills.navigation.costmap import RollingCostmap
from mmexec.skills.navigation.dwa import DwaConfig, DwaPlanner, DwaStatus, PathFollower, rollouts
from mmexec.skills.navigation.limits import LOCOBOT_KOBUKI, UR5E_PLATFORM, BaseLimits, reachable
from mmexec.skills.navigation.obstacles import Circles
from mmexec.skills.navigation.social import social_cost

DT = 0.05


def _costmap(blocks=(), w=200, h=120):
    """A walled room 10 x 6 m with extra occupied rectangles (x0, y0, x1, y1) [m]."""
    d = np.zeros((h, w), dtype=np.int8)
    d[0, :] = d[-1, :] = d[:, 0] = d[:, -1] = 100
    for x0, y0, x1, y1 in blocks:
        d[round(y0 / 0.05) : round(y1 / 0.05), round(x0 / 0.05) : round(x1 / 0.05)] = 100
    cm = RollingCostmap(OccupancyGrid(data=d, resolution=0.05))
    return cm


def _circles(centres, safety, person=False, velocities=None):
    c = np.asarray(centres, dtype=float).reshape(-1, 2)
    n = c.shape[0]
    s = np.full(n, float(safety))
    v = np.zeros((n, 2)) if velocities is None else np.asarray(velocities, dtype=float).reshape(-1, 2)
    return Circles(c, s - 0.3, s, v, np.arange(n), np.full(n, person))


def _planner(path, cfg=None, now=0.0):
    p = DwaPlanner(cfg or DwaConfig())
    p.set_path(path, now)
    return p


def _step(p, cm, pose, v0=0.0, w0=0.0, circles=None, now=0.0, v_cap=None):
    cm.recentre(pose.x, pose.y)
    return p.step(pose, v0, w0, DT, now, cm, circles if circles is not None else Circles(), v_cap)


# ---------------------------------------------------------------------- window and rollouts


def test_reachable_interval():
    assert reachable(0.3, 0.0, 0.7, 0.05) == (0.25, 0.35)
    assert reachable(0.68, 0.0, 0.7, 0.05) == (0.63, 0.7)
    assert reachable(0.9, 0.0, 0.7, 0.05) == (0.85, 0.85)      # over the limit: brake at full rate
    assert reachable(-0.3, 0.0, 0.7, 0.05) == (-0.25, -0.25)


def test_dynamic_window_from_limits():
    lim = BaseLimits(max_v=0.7, min_v=-0.1, max_w=3.0, accel_v=1.0, accel_w=3.5)
    assert lim.window(0.0, 0.0, 0.05) == pytest.approx((-0.05, 0.05, -0.175, 0.175))
    assert lim.window(0.5, 2.9, 0.05, v_cap=0.2) == pytest.approx((0.45, 0.45, 2.725, 3.0))
    assert lim.brake(0.5, -1.0, 0.05) == pytest.approx((0.45, -0.825))
    assert lim.brake(0.02, 0.1, 0.05) == (0.0, 0.0)
    for preset in (LOCOBOT_KOBUKI, UR5E_PLATFORM):
        assert preset.validate() == []
    assert LOCOBOT_KOBUKI.radius == 0.178 and UR5E_PLATFORM.radius == 0.405


def test_rollouts_hold_a_constant_velocity_on_exact_arcs():
    pose = Pose2D(1.0, -0.5, 0.3)
    v = np.array([0.5, 0.5, 0.2])
    w = np.array([0.0, 1.2, -2.0])
    traj, speed, dist = rollouts(pose, 0.5, 1.2, v, w, 0.1, 15, 1.0, 3.5)
    t = 0.1 * np.arange(1, 16)
    # rollout 1 starts at the target: an exact arc
    x = pose.x + v[1] / w[1] * (np.sin(pose.theta + w[1] * t) - math.sin(pose.theta))
    y = pose.y - v[1] / w[1] * (np.cos(pose.theta + w[1] * t) - math.cos(pose.theta))
    np.testing.assert_allclose(traj[1, :, 0], x, atol=2e-3)
    np.testing.assert_allclose(traj[1, :, 1], y, atol=2e-3)
    np.testing.assert_allclose(traj[1, :, 2], pose.theta + w[1] * t)
    np.testing.assert_allclose(dist[1], 0.5 * t)
    # rollout 2 ramps: speed falls 0.5 -> 0.2 at 1 m/s^2, yaw rate 1.2 -> -2 at 3.5 rad/s^2
    np.testing.assert_allclose(speed[2], np.maximum(0.2, 0.5 - t))
    t_kink = 3.2 / 3.5                    # exact integral of the ramp; midpoint error at the kink only
    assert traj[2, -1, 2] == pytest.approx(pose.theta + 1.2 * t_kink - 1.75 * t_kink**2 - 2.0 * (1.5 - t_kink), abs=1e-3)


def test_window_samples_span_the_reachable_targets():
    p = DwaPlanner(DwaConfig(limits=LOCOBOT_KOBUKI, window_time=0.5))
    vs, ws = p.window_samples(0.3, 1.0, v_cap=None)
    assert vs.min() == pytest.approx(0.0) and vs.max() == pytest.approx(0.7)
    assert ws.min() == pytest.approx(1.0 - 1.75) and ws.max() == pytest.approx(1.0 + 1.75)
    assert (ws == 0.0).any()                      # driving straight is always a candidate
    vs, _ = p.window_samples(0.3, 0.0, v_cap=0.2)
    assert vs.max() == pytest.approx(0.2)


# ---------------------------------------------------------------------- following the path


def test_path_follower_resamples_and_never_goes_back():
    f = PathFollower([(0.0, 0.0), (2.0, 0.0), (2.0, 1.0)], 0.05)
    assert f.length == pytest.approx(3.0) and len(f.points) == 61
    assert f.advance(1.0, 0.2, 1.0) == 20
    assert f.advance(0.5, 0.0, 1.0) == 20         # the robot fell back: progress stays
    assert f.remaining() == pytest.approx(2.0)
    np.testing.assert_allclose(f.points[f.ahead(1.5)], [2.0, 0.5])
    assert f.heading[-1] == pytest.approx(math.pi / 2)


def test_open_space_drives_straight_along_the_path():
    cm = _costmap()
    p = _planner([(1.0, 3.0), (8.0, 3.0)])
    r = _step(p, cm, Pose2D(1.0, 3.0, 0.0))
    assert r.status is DwaStatus.OK and not r.path_blocked
    assert r.v == pytest.approx(LOCOBOT_KOBUKI.accel_v * DT)   # accelerating as hard as allowed
    assert r.w == pytest.approx(0.0)
    assert r.carrot.x == pytest.approx(1.5) and r.carrot.theta == pytest.approx(0.0)
    assert r.n_admissible == r.n_rollouts


def test_a_narrow_passage_on_the_path_is_driven_into():
    """A 0.5 m gap 0.6 m ahead (7 cm beyond the radius each side, less than the 0.4 m
    clearance scale): the base drives on into it, as the path asks, rather than creeping
    or standing (with the fixed scale, the clearance penalty of reaching the squeeze
    outweighed the progress)."""
    cm = _costmap(blocks=[(2.0, 0.0, 2.6, 2.75), (2.0, 3.25, 2.6, 6.0)])
    path = [(1.4, 3.0), (4.0, 3.0)]

    def drive(cfg):
        p = _planner(path, cfg)
        pose, v, top = Pose2D(1.4, 3.0, 0.0), 0.05, 0.0
        for k in range(60):                                          # 3 s
            r = _step(p, cm, pose, v0=v, now=k * DT)
            v, top = r.v, max(top, r.v)
            pose = Pose2D(pose.x + v * DT, pose.y, 0.0)
        return pose.x, top

    x, _ = drive(DwaConfig())
    assert x > 2.2
    assert _planner(path).path_gap(np.array([[2.3, 3.0]]), cm, Circles()) == pytest.approx(0.25 - 0.178, abs=0.03)
    x_fixed, _ = drive(replace(DwaConfig(), min_clearance_scale=0.4))  # the clearance scale fixed at 0.4 m
    assert x_fixed < 1.6


def test_a_path_to_the_left_turns_left():
    cm = _costmap()
    p = _planner([(2.0, 2.0), (2.0, 5.0)])
    r = _step(p, cm, Pose2D(2.0, 2.0, 0.0), v0=0.3)
    assert r.w > 0.0


def _drive(p, cm, pose, v, w, ticks, box):
    """Close the loop on the DWA alone; the true gap to ``box`` (x0, y0, x1, y1) must stay
    above the robot radius less the costmap's half-cell accuracy."""
    r = None
    for k in range(ticks):
        r = _step(p, cm, pose, v, w, now=k * DT)
        v, w = r.v, r.w
        pose = Pose2D(pose.x + v * DT * math.cos(pose.theta + w * DT / 2),
                      pose.y + v * DT * math.sin(pose.theta + w * DT / 2), pose.theta + w * DT)
        x0, y0, x1, y1 = box
        gap = math.hypot(max(x0 - pose.x, 0.0, pose.x - x1), max(y0 - pose.y, 0.0, pose.y - y1))
        assert gap >= LOCOBOT_KOBUKI.radius - 0.025
    return pose, v, r


def test_an_obstacle_on_the_path_is_not_hit_and_is_reported():
    box = (3.0, 3.1, 3.3, 3.6)                                 # 8 cm into the band the path sweeps
    cm = _costmap(blocks=[box])
    pose, v, r = _drive(_planner([(1.0, 3.0), (8.0, 3.0)]), cm, Pose2D(1.6, 3.0, 0.0), 0.5, 0.0, 80, box)
    assert r.path_blocked                                      # the caller re-plans
    # the re-planned path bends round the box: followed without touching it
    detour = [(pose.x, pose.y), (2.6, 2.75), (3.7, 2.75), (4.5, 3.0), (8.0, 3.0)]
    pose, _, r = _drive(_planner(detour), cm, pose, v, 0.0, 100, box)
    assert pose.x > 4.0 and not r.path_blocked


def test_a_robot_that_cannot_stop_in_time_gets_no_trajectory():
    cm = _costmap(blocks=[(2.4, 0.0, 2.6, 6.0)])               # a wall across the room
    p = _planner([(1.0, 3.0), (8.0, 3.0)])
    r = _step(p, cm, Pose2D(2.1, 3.0, 0.0), v0=0.7)           # 0.12 m short of touching it
    assert r.status is DwaStatus.NO_TRAJECTORY and r.n_admissible == 0
    assert (r.v, r.w) == pytest.approx((0.65, 0.0))           # the command brakes
    # with room to brake, the base may drive on, but it stops short of the wall
    _, v, r = _drive(p, cm, Pose2D(1.5, 3.0, 0.0), 0.7, 0.0, 80, (2.4, 0.0, 2.6, 6.0))
    assert v < 0.1 and r.path_blocked


def test_moving_people_are_predicted():
    cm = _costmap()
    p = _planner([(1.0, 3.0), (8.0, 3.0)])
    still = _step(p, cm, Pose2D(1.0, 3.0, 0.0), v0=0.5, circles=_circles([[2.0, 4.2]], 0.6, person=True))
    walking = _step(p, cm, Pose2D(1.0, 3.0, 0.0), v0=0.5,
                    circles=_circles([[2.0, 4.2]], 0.6, person=True, velocities=[[0.0, -0.8]]))
    # a person 1.2 m to the side is harmless standing, not when walking into the path
    assert still.v > walking.v or still.n_admissible > walking.n_admissible


def test_the_social_cost_keeps_the_robot_out_of_personal_space():
    """Near a person the weighted social term picks a rollout (slower, or bent away) whose
    largest social cost is lower than the one chosen without it."""
    cm = _costmap()
    pose = Pose2D(1.8, 3.0, 0.0)
    people = _circles([[2.6, 3.55]], 0.4, person=True)
    worst = []
    for w_social in (0.0, 2.0):
        cfg = DwaConfig(w_social=w_social)
        r = _step(_planner([(1.0, 3.0), (8.0, 3.0)], cfg), cm, pose, v0=0.4, circles=people)
        worst.append(float(social_cost(r.trajectory[:, :2], people.centres, cfg.social).max()))
    assert worst[1] < 0.5 * worst[0]


def test_speed_cap_and_goal_reached():
    cm = _costmap()
    p = _planner([(1.0, 3.0), (8.0, 3.0)])
    r = _step(p, cm, Pose2D(2.0, 3.0, 0.0), v0=0.4, v_cap=0.2)
    assert r.v <= 0.4 and r.trajectory.shape[0] > 0
    r = _step(p, cm, Pose2D(7.95, 3.02, 0.0), v0=0.1, w0=0.2)
    assert r.status is DwaStatus.GOAL_REACHED
    assert (r.v, r.w) == pytest.approx((0.05, 0.025))


def test_path_blocked_by_an_obstacle_but_not_by_a_person():
    cm = _costmap(blocks=[(3.4, 2.8, 3.6, 3.2)])              # on the path, 1.5 m ahead
    p = _planner([(1.0, 3.0), (8.0, 3.0)])
    r = _step(p, cm, Pose2D(2.0, 3.0, 0.0))
    assert r.path_blocked and r.blocked_at == pytest.approx(3.4 - 0.178 - 2.0, abs=0.08)
    clear = _costmap()
    assert not _step(_planner([(1.0, 3.0), (8.0, 3.0)]), clear, Pose2D(2.0, 3.0, 0.0)).path_blocked
    chair = _circles([[3.0, 3.1]], 0.5)
    person = _circles([[3.0, 3.1]], 0.5, person=True)
    assert _step(_planner([(1.0, 3.0), (8.0, 3.0)]), clear, Pose2D(2.0, 3.0, 0.0), circles=chair).path_blocked
    assert not _step(_planner([(1.0, 3.0), (8.0, 3.0)]), clear, Pose2D(2.0, 3.0, 0.0), circles=person).path_blocked
    far = _costmap(blocks=[(6.4, 2.8, 6.6, 3.2)])             # beyond blocked_lookahead
    assert not _step(_planner([(1.0, 3.0), (8.0, 3.0)]), far, Pose2D(2.0, 3.0, 0.0)).path_blocked


def test_stuck_after_no_progress_and_reset():
    cm = _costmap()
    cfg = DwaConfig(stuck_time=2.0, stuck_progress=0.1)
    p = _planner([(1.0, 3.0), (8.0, 3.0)], cfg, now=0.0)
    pose = Pose2D(1.0, 3.0, 0.0)
    assert _step(p, cm, pose, now=1.9).status is DwaStatus.OK
    assert _step(p, cm, pose, now=2.1).status is DwaStatus.STUCK     # no progress for 2 s
    p.reset_progress(2.1)
    assert _step(p, cm, pose, now=3.0).status is DwaStatus.OK
    moved = Pose2D(1.2, 3.0, 0.0)                                     # 0.2 m of progress
    assert _step(p, cm, moved, now=4.0).status is DwaStatus.OK
    assert _step(p, cm, moved, now=5.9).status is DwaStatus.OK
    assert _step(p, cm, moved, now=6.1).status is DwaStatus.STUCK


def test_dwa_needs_a_path_and_a_valid_config():
    p = DwaPlanner()
    with pytest.raises(RuntimeError, match="set_path"):
        p.step(Pose2D(), 0.0, 0.0, DT, 0.0, _costmap(), Circles())
    with pytest.raises(ValueError, match="n_v and n_w"):
        DwaPlanner(replace(DwaConfig(), n_v=1))
