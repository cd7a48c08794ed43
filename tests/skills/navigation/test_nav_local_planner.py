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
from mmexec.skills.navigation.synthetic import Walker, run_closed_loop

MARGIN = 0.05
START, GOAL = Pose2D(1.0, 3.0, 0.0), (9.0, 3.0)
#: poles the map does not hold, one right beside the straight line the first A* path takes
POLES = np.array([[3.0, 3.35], [6.5, 4.0], [7.5, 2.9]])
POLE_RADII = np.array([0.12, 0.2, 0.15])
#: a person who steps across the corridor ahead once the robot passes x = 3.5
WALKER = Walker(start=(5.5, 5.2), velocity=(0.0, -0.5), radius=0.22, trigger_x=3.5)


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
