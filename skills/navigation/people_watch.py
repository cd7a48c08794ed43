"""The lidar's tracked people while the base stands: for skills that look or act with
the base at rest among people (the search's views).

The drive feeds each new scan to the run's local planner (its costmap and tracks) only
while it drives; a skill that keeps the base standing would see the tracks of the last
drive, coasting and then dropped. A :class:`PeopleWatch` feeds the newest scan, when its
stamp is new, to the same planner (so the tracks carry over to the next drive as they do
between drives) and hands out the people tracked now, in ``map``. Only with
``nav.local_planner`` and a lidar (:meth:`PeopleWatch.for_robot`): without them nobody
is tracked.
"""

from __future__ import annotations

import math
from typing import Self

from mmexec.skills.base import SkillContext
from mmexec.skills.navigation.local_drive import local_planner
from mmexec.skills.navigation.local_planner import LocalPlanner
from mmexec.skills.navigation.navigate import local_drive_config, nav_settings
from mmexec.skills.navigation.obstacles import Circles

__all__ = ["PeopleWatch"]


class PeopleWatch:
    """The run's local planner's tracks, kept up to date from the lidar by :meth:`observe`."""

    def __init__(self, ctx: SkillContext, planner: LocalPlanner) -> None:
        self.ctx, self.planner = ctx, planner
        self._stamp = -math.inf

    @classmethod
    def for_robot(cls, ctx: SkillContext) -> Self | None:
        """A watch on the run's local planner; None without ``nav.local_planner``, a base,
        a lidar or a map (no people are tracked then)."""
        base, lidar = ctx.robot.base, ctx.robot.lidar
        if base is None or lidar is None or ctx.robot.occupancy is None or not nav_settings(ctx).local_planner:
            return None
        return cls(ctx, local_planner(ctx, local_drive_config(ctx, base, None).planner))

    def observe(self) -> None:
        """Feed the lidar's newest scan, when it is new, to the tracks (taken with the
        base at its current pose)."""
        lidar, base = self.ctx.robot.lidar, self.ctx.robot.base
        assert lidar is not None and base is not None
        scan = lidar.scan()
        if scan is not None and scan.stamp > self._stamp:
            self._stamp = scan.stamp
            self.planner.observe(scan, base.state().pose)

    def people(self) -> Circles:
        """The tracked people now: centres (k, 2) [m, map], covering radii (k,) [m] and
        velocities (k, 2) [m/s]."""
        return self.planner.circles_at(self.ctx.clock.now()).people
