from __future__ import annotations

import math

import numpy as np
import pytest

from mmexec.drivers.geometry import wrap_angle
from mmexec.drivers.interfaces import OccupancyGrid, Pose2D
from mmexec.skills.navigation.astar import plan_path, simplify_path
from mmexec.skills.navigation.grid import inflate
from mmexec.skills.navigation.tracker import PathTracker, TrackerConfig


def _simulate(tracker, pose, dt=0.05, steps=2000, lag=0.0):
    """Integrate a unicycle exactly (arc per tick); ``lag`` in [0, 1) makes the measured
    velocity trail the command like a real base."""
    v_meas = w_meas = 0.0
    cmds = []
    traj = [pose]
    for _ in range(steps):
        v, w, done = tracker.step(pose, v_meas, w_meas, dt)
        cmds.append((v, w))
        if done:
            return pose, cmds, traj, True
        v_act = lag * v_meas + (1 - lag) * v
        w_act = lag * w_meas + (1 - lag) * w
        th = pose.theta
        if abs(w_act) > 1e-9:
            x = pose.x + v_act / w_act * (math.sin(th + w_act * dt) - math.sin(th))
            y = pose.y - v_act / w_act * (math.cos(th + w_act * dt) - math.cos(th))
        else:
            x = pose.x + v_act * dt * math.cos(th)
            y = pose.y + v_act * dt * math.sin(th)
        pose = Pose2D(x, y, wrap_angle(th + w_act * dt))
        v_meas, w_meas = v_act, w_act
        traj.append(pose)
    return pose, cmds, traj, False


def _check_limits(cmds, cfg, dt):
    prev = (0.0, 0.0)
    for v, w in cmds:
        assert abs(v) <= cfg.max_v + 1e-9
        assert abs(w) <= cfg.max_w + 1e-9
        assert abs(v - prev[0]) <= cfg.accel_v * dt + 1e-9
        assert abs(w - prev[1]) <= cfg.accel_w * dt + 1e-9
        prev = (v, w)


def test_converges_on_l_path_with_final_heading_within_limits():
    cfg = TrackerConfig(max_v=0.5, max_w=1.2, accel_v=0.6, accel_w=2.0)
    path = [(0.0, 0.0), (2.0, 0.0), (2.0, 1.5)]
    tr = PathTracker(path, cfg, goal_heading=math.pi)
    pose, cmds, traj, done = _simulate(tr, Pose2D(0.0, 0.0, -math.pi / 2), dt=0.05)
    assert done
    assert math.hypot(pose.x - 2.0, pose.y - 1.5) <= cfg.goal_tolerance + 0.02
    assert abs(wrap_angle(pose.theta - math.pi)) <= cfg.heading_tolerance + 0.02
    _check_limits(cmds, cfg, 0.05)
    # it followed the corner: it never strays far from the L
    for p in traj:
        d = min(abs(p.y) if p.x <= 2.0 else math.hypot(p.x - 2, p.y), abs(p.x - 2.0) if 0 <= p.y <= 1.5 else 9)
        assert d < 0.4


def test_converges_with_lagging_base_and_planned_path():
    data = np.zeros((60, 80), dtype=np.int8)
    data[0:40, 38:42] = 100
    cm = inflate(OccupancyGrid(data, 0.05), 0.18, 0.02)
    raw = plan_path(cm, (0.5, 0.5), (3.5, 0.5))
    assert raw is not None
    path = simplify_path(cm, raw)
    cfg = TrackerConfig()
    tr = PathTracker(path, cfg)
    pose, cmds, traj, done = _simulate(tr, Pose2D(0.5, 0.5, 0.0), dt=0.1, lag=0.3)
    assert done
    assert math.hypot(pose.x - 3.5, pose.y - 0.5) <= cfg.goal_tolerance + 0.03
    _check_limits(cmds, cfg, 0.1)
    assert sum(1 for p in traj if not cm.is_free(p.x, p.y)) == 0


def test_goal_behind_turns_in_place_first():
    tr = PathTracker([(0.0, 0.0), (-1.0, 0.0)], TrackerConfig())
    v, w, done = tr.step(Pose2D(0, 0, 0), 0.0, 0.0, 0.05)
    # straight behind is a tie: wrap_angle puts it at -pi, so it turns clockwise
    assert v == 0.0 and w < 0 and not done and tr.phase == "turn"


def test_already_at_goal_is_done_at_once_and_bad_dt():
    tr = PathTracker([(1.0, 1.0)], TrackerConfig(), goal_heading=0.0)
    assert tr.step(Pose2D(1.0, 1.0, 0.0), 0.0, 0.0, 0.05) == (0.0, 0.0, True)
    with pytest.raises(ValueError):
        tr.step(Pose2D(), 0.0, 0.0, 0.0)
    with pytest.raises(ValueError):
        PathTracker([], TrackerConfig())
