"""People in the way of the UR platforms (issue 12, part 3): the global re-plan leaves out
the lidar's marks on the people it leaves out (and the trail behind them), so two people
standing in a passage are waited for, not taken for a wall that closes every way."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mmexec.drivers.interfaces import OccupancyGrid, Pose2D
from mmexec.skills.base import SkillFailure
from mmexec.skills.navigation.astar import plan_path
from mmexec.skills.navigation.costmap import RollingCostmap
from mmexec.skills.navigation.grid import inflate, world_to_cell
from mmexec.skills.navigation.limits import UR5E_PLATFORM
from mmexec.skills.navigation.local_planner import PERSON_TRAIL, LocalPlanner, LocalPlannerConfig
from mmexec.skills.navigation.obstacles import Circles
from mmexec.skills.navigation.synthetic import cast_scan

MARGIN = 0.03
START, GOAL = Pose2D(1.5, 1.5, 0.0), (8.5, 1.5)
PEOPLE = np.array([[4.0, 1.05], [4.0, 1.95]])   # side by side across the 1.6 m passage
RADII = np.array([0.22, 0.22])


def _passage() -> OccupancyGrid:
    d = np.zeros((60, 200), dtype=np.int8)         # 10 x 3 m at 5 cm; a 1.6 m passage at y 0.7-2.3
    d[:14, :] = d[-14:, :] = 100
    d[:, 0] = d[:, -1] = 100
    return OccupancyGrid(data=d, resolution=0.05)


def _planner_with_people(person: bool) -> LocalPlanner:
    grid = _passage()
    planner = LocalPlanner(grid, LocalPlannerConfig.for_base(UR5E_PLATFORM, MARGIN))
    planner.observe(cast_scan(grid, START, PEOPLE, RADII, stamp=0.0), START)
    # the tracker's view of them (people: they walked here; furniture otherwise)
    planner._tracks = Circles(PEOPLE.copy(), RADII.copy(), RADII + UR5E_PLATFORM.radius + MARGIN,
                              np.zeros((2, 2)), np.arange(2), np.full(2, person))
    return planner


def _path(planner: LocalPlanner) -> list | None:
    cm = inflate(planner.replan_grid(0.0), UR5E_PLATFORM.radius, MARGIN)
    return plan_path(cm, (START.x, START.y), GOAL)


def test_people_standing_in_a_passage_leave_the_replan_a_way():
    planner = _planner_with_people(person=True)
    assert planner.costmap.marks.any()                       # the lidar marked them
    assert _path(planner) is not None                        # people move on: the way is kept
    furniture = _planner_with_people(person=False)           # the same circles, not people
    assert _path(furniture) is None


def test_once_the_wait_is_spent_people_standing_close_the_way():
    planner = _planner_with_people(person=True)
    t = 0.0
    while planner.giving_way(planner.circles_at(t), Pose2D(3.0, 1.5, 0.0), t):
        t += 0.05
    assert planner.people_wait.spent
    assert _path(planner) is None


def test_merged_grid_ignores_marks_in_the_discs_but_not_pinned_ones():
    grid = _passage()
    cm = RollingCostmap(grid)
    cm.recentre(4.0, 1.5)
    trail = np.array([[4.0 + 0.3, 1.05], [4.0 + 0.15 + PERSON_TRAIL, 1.05]])   # behind the first person
    for xy in (*PEOPLE, *trail):
        r, c = world_to_cell(grid, *xy)
        cm.marks[r - cm.r0, c - cm.c0] = True
    cm.pin(np.array([[4.0, 1.25]]))                           # a bumper contact beside them
    merged = cm.merged_grid(ignore=(PEOPLE, RADII + PERSON_TRAIL))
    for xy in (*PEOPLE, *trail):
        assert merged.data[world_to_cell(grid, *xy)] == 0
    assert merged.data[world_to_cell(grid, 4.0, 1.25)] == 100
    assert (cm.merged_grid().data[cm.marks.nonzero()[0] + cm.r0, cm.marks.nonzero()[1] + cm.c0] == 100).all()


#: [m] where the person stops: 0.5 m beyond the viewpoint at (4.0, 1.5)
STAND_X = 4.5


def _walk_then_stand(t: float) -> tuple[float, float, float]:
    """A person (0.2 m) walking west along y = 1.5 from x = 5.5 at 0.5 m/s, standing at
    x = STAND_X from t = 2 s on."""
    return (max(STAND_X, 5.5 - 0.5 * t), 1.5, 0.2)


def _drive_among(viewpoint: bool, events: list) -> tuple[Pose2D | None, SkillFailure | None]:
    from test_nav_local_drive import _ctx, _robot, room

    from mmexec.skills.navigation.navigate import drive_path

    robot = _robot(room(), Pose2D(1.0, 1.5, 0.0), circles=[_walk_then_stand(0.0)], nav={"recoveries": 1})
    ctx = _ctx(robot, events)
    gen = drive_path(ctx, Pose2D(4.0, 1.5, 0.0), "the viewpoint", timeout=90.0, viewpoint=viewpoint)
    t0 = robot.clock.now()
    try:
        for _ in range(4000):
            next(gen)
            robot.spin(0.05)
            robot.lidar.circles = [_walk_then_stand(robot.clock.now() - t0)]
    except StopIteration as stop:
        return stop.value, None
    except SkillFailure as failure:
        return None, failure
    raise AssertionError("the drive did not end")


@pytest.mark.slow
def test_a_viewpoint_someone_stands_by_is_looked_from_short_of_it():
    """Someone walks up and stands 0.5 m beyond a viewpoint: the base, kept out of the
    zone round them (and the DWA's look-ahead), waits its patience, then looks from where
    it stands (within VIEW_SHORT), turned to the viewpoint's heading. Any other goal
    keeps trying and fails after its recoveries."""
    from mmexec.skills.navigation.navigate import VIEW_SHORT

    events: list = []
    end, failure = _drive_among(True, events)
    assert failure is None and end is not None
    short = [f for e, f in events if e == "nav_view_short"]
    assert len(short) == 1 and 0.0 < short[0]["short"] <= VIEW_SHORT
    assert end.distance_to(Pose2D(4.0, 1.5)) <= VIEW_SHORT and abs(end.theta) <= 0.05
    assert math.hypot(end.x - STAND_X, end.y - 1.5) > 0.2 + 0.178         # never into them
    events.clear()
    end, failure = _drive_among(False, events)
    assert end is None and failure is not None and not [e for e, _ in events if e == "nav_view_short"]
