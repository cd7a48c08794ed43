"""The local navigation stack in closed loop (pure Python: a unicycle, a static map, poles
the map lacks and a walking person): DWA + CLF-CBF reaches the goal with every barrier
kept, and without the filter the DWA alone breaks one."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from mmexec.drivers.interfaces import OccupancyGrid, Pose2D
from mmexec.skills.navigation.limits import LOCOBOT_KOBUKI, UR5E_PLATFORM
from mmexec.skills.navigation.local_planner import LocalPlanner, LocalPlannerConfig
from mmexec.skills.navigation.synthetic import Walker, cast_scan, run_closed_loop, unicycle_step

MARGIN = 0.05
START, GOAL = Pose2D(1.0, 3.0, 0.0), (9.0, 3.0)
#: poles the map does not hold, one right beside the straight line the first A* path takes
POLES = np.array([[3.0, 3.35], [6.5, 4.0], [7.5, 2.9]])
POLE_RADII = np.array([0.12, 0.2, 0.15])
#: a person who steps across the corridor ahead once the robot passes x = 4.0 (timed so that
#: the DWA alone meets them: with a trigger at 3.5 m it kept 0.42 m from them once the
#: DWA stopped hesitating at narrow passages (dwa.py, the clearance scale); at 4.0 it overlaps them)
WALKER = Walker(start=(5.5, 5.2), velocity=(0.0, -0.5), radius=0.22, trigger_x=4.0)


def _room() -> OccupancyGrid:
    d = np.zeros((120, 200), dtype=np.int8)        # 10 x 6 m at 5 cm
    d[0, :] = d[-1, :] = d[:, 0] = d[:, -1] = 100
    d[0:50, 95:105] = 100                          # a wall stub from the bottom, x 4.75-5.25
    return OccupancyGrid(data=d, resolution=0.05)


def test_dwa_and_cbf_reach_the_goal_keeping_every_barrier():
    cfg = LocalPlannerConfig.for_base(LOCOBOT_KOBUKI, MARGIN)   # alpha 1.0 / 2.0 (the defaults)
    rec = run_closed_loop(_room(), START, GOAL, POLES, POLE_RADII, WALKER, cfg, t_max=120.0)
    assert rec.reached, rec
    # h = |p - c|^2 - (r + robot radius + margin)^2 >= 0 at every step, for every pole and
    # the person: the gap beyond both radii never fell below the margin
    assert rec.min_pole_gap >= MARGIN, rec
    assert rec.min_person_gap >= MARGIN, rec
    assert rec.barrier_active > 0 and rec.replans >= 1, rec


def test_without_the_filter_the_dwa_breaks_a_barrier():
    """The same world with the DWA's command sent unfiltered: its sampled, predicted check
    lets the person (who keeps walking) inside the margin; the filter did not (above)."""
    cfg = LocalPlannerConfig.for_base(LOCOBOT_KOBUKI, MARGIN, use_cbf=False)
    rec = run_closed_loop(_room(), START, GOAL, POLES, POLE_RADII, WALKER, cfg, t_max=120.0,
                          stop_when=lambda r: min(r.min_pole_gap, r.min_person_gap) < MARGIN)
    assert min(rec.min_pole_gap, rec.min_person_gap) < MARGIN, rec
    assert rec.filtered == 0


def test_configs_agree_on_the_base():
    cfg = LocalPlannerConfig.for_base(UR5E_PLATFORM, 0.03)
    assert cfg.validate() == []
    assert cfg.obstacles.robot_radius == cfg.social.robot_radius == 0.405
    assert cfg.dwa.limits == cfg.cbf.limits == UR5E_PLATFORM and cfg.obstacles.margin == 0.03
    LocalPlanner(_room(), cfg)
    bad = replace(cfg, cbf=replace(cfg.cbf, limits=LOCOBOT_KOBUKI))
    with pytest.raises(ValueError, match="use for_base"):
        LocalPlanner(_room(), bad)


def _stand_off_a_person(person_x: float, wall_behind: bool) -> tuple[list[float], list[float], int]:
    """A base standing at (3, 3) facing +x, its path straight on to (9, 3); someone stands
    at ``person_x`` on that line (inside the filter's zone when close). 3 s of ticks: the
    enforced barrier's smallest h, the base's x, and how many commands were escapes."""
    grid = _room()
    if wall_behind:
        d = np.array(grid.data, copy=True)
        d[50:70, 55:57] = 100                      # a wall 0.2 m behind the base's back (x 2.75-2.85)
        grid = OccupancyGrid(data=d, resolution=grid.resolution)
    cfg = LocalPlannerConfig.for_base(LOCOBOT_KOBUKI, MARGIN)
    planner = LocalPlanner(grid, cfg)
    planner.set_path([(3.0, 3.0), (9.0, 3.0)], 0.0)
    pose, v, w = Pose2D(3.0, 3.0, 0.0), 0.0, 0.0
    hs, xs, escapes = [], [], 0
    for k in range(60):
        t = 0.05 * k
        scan = cast_scan(grid, pose, np.array([[person_x, 3.0]]), np.array([0.2]), n_beams=400, stamp=t)
        cmd = planner.step(pose, v, w, t, 0.05, scan)
        assert cmd.cbf is not None
        if cmd.cbf.h.size:
            hs.append(float(cmd.cbf.h.min()))
        escapes += cmd.cbf.escaped
        v, w = cmd.v, cmd.w
        pose = unicycle_step(pose, v, w, 0.05)
        xs.append(pose.x)
    return hs, xs, escapes


def test_someone_inside_the_zone_is_backed_away_from_where_there_is_room():
    """A person 0.12 m from the footprint (inside the zone: covering circle + footprint +
    5 cm margin): the filter's escape backs the base off at low speed until h >= 0."""
    hs, xs, escapes = _stand_off_a_person(3.5, wall_behind=False)
    assert hs[0] < 0.0 and escapes > 0
    assert min(xs) < 2.95 and min(np.diff([3.0, *xs])) >= -0.1 * 0.05 - 1e-9   # back, never faster than 0.1 m/s
    assert hs[-1] >= 0.0


def test_no_escape_into_what_the_lidar_sees_behind():
    """The same with a wall 0.2 m behind the base's back: the room behind is what the
    costmap shows, so the base does not back into the wall (it stands, h stays < 0)."""
    hs, xs, _ = _stand_off_a_person(3.5, wall_behind=True)
    assert hs[0] < 0.0
    assert min(xs) >= 3.0 - 0.05                   # at most the few cm the room left
    planner = LocalPlanner(_room(), LocalPlannerConfig.for_base(LOCOBOT_KOBUKI, MARGIN))
    for pose in (Pose2D(3.0, 3.0, 0.0), Pose2D(0.3, 3.0, 0.0)):
        planner.observe(cast_scan(_room(), pose, np.zeros((0, 2)), np.zeros(0), stamp=0.0), pose)
        room = planner.escape_room(pose)
        if pose.x == 3.0:
            assert room == (pytest.approx(0.1), pytest.approx(0.1))
        else:
            assert room[0] == 0.0 and room[1] == pytest.approx(0.1)    # the outer wall 0.25 m behind the centre


def test_a_person_who_keeps_the_sims_distance_leaves_h_positive():
    """The sim's people stop 0.3 m from the footprint: that is outside the zone, so the
    enforced barrier stays >= 0 and the base is not pushed back."""
    hs, xs, escapes = _stand_off_a_person(3.0 + 0.178 + 0.3 + 0.2, wall_behind=False)
    assert min(hs) >= 0.0 and escapes == 0 and min(xs) >= 3.0 - 1e-9


def test_replans_go_round_people_standing_once_the_wait_is_spent():
    from mmexec.skills.navigation.obstacles import Circles
    planner = LocalPlanner(_room(), LocalPlannerConfig.for_base(LOCOBOT_KOBUKI, MARGIN))
    planner.observe(cast_scan(_room(), START, np.zeros((0, 2)), np.zeros(0), stamp=0.0), START)
    standing, walking = np.array([[2.5, 4.0]]), np.array([[3.5, 4.0]])   # within the window round START
    planner._tracks = Circles(np.vstack([standing, walking]), np.full(2, 0.2), np.full(2, 0.43),
                              np.array([[0.0, 0.0], [0.8, 0.0]]), np.arange(2), np.ones(2, dtype=bool))

    def occupied(grid, xy):
        col, row = int(xy[0] / grid.resolution), int(xy[1] / grid.resolution)
        return grid.data[row, col] >= 50

    g = planner.replan_grid(0.0)
    assert not occupied(g, standing[0]) and not occupied(g, walking[0])
    t = 0.0
    while planner.giving_way(planner.circles_at(t), Pose2D(2.5, 3.2, 0.0), t):
        t += 0.05
    assert t == pytest.approx(planner.config.social.patience, abs=0.1)
    g = planner.replan_grid(0.0)
    assert occupied(g, standing[0]) and not occupied(g, walking[0])
