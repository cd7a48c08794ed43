"""The ``localize`` skill: global localisation, then turn in place until the localiser
has converged (docs/localization.md, "In the executive").

A recovery for a robot that does not know where it is: ``navigate`` refuses to start
while the localiser has not converged, and the fetch mission runs ``localize`` before
trying again (trees/fetch/drive.yaml). Without ``force`` a robot already localised, or
one without a localiser, succeeds at once without moving, so the skill can stand in any
recovery.
"""

from __future__ import annotations

import math

from mmexec.drivers.interfaces import BaseState
from mmexec.skills.base import (
    FailureKind,
    Output,
    Param,
    SkillContext,
    SkillFailure,
    SkillGen,
    skill,
)
from mmexec.skills.localization.localizer import LocalizingBase
from mmexec.skills.primitives import Step, motion_loop

__all__ = ["localize", "spread"]


def spread(st: BaseState) -> tuple[float, float]:
    """The position [m] and heading [rad] standard deviations of a base state's
    covariance (0, 0 without one)."""
    if st.covariance is None:
        return 0.0, 0.0
    c = st.covariance
    return math.sqrt(max(c[0][0], c[1][1], 0.0)), math.sqrt(max(c[2][2], 0.0))


@skill(
    "localize",
    params=[
        Param("force", bool, default=False,
              doc="re-localise even when the localiser has converged (a suspected kidnap)"),
        Param("turn_speed", float, unit="rad/s", default=0.6, doc="turn rate while localising"),
        Param("min_updates", int, default=5, doc="filter updates after the reset before convergence counts"),
        Param("min_turn", float, unit="rad", default=2 * math.pi,
              doc="turn at least this far (a full turn shows the filter every direction, and the reflectors "
                  "a fix where they are in view: a cloud that converged early on a look-alike place moves on)"),
        Param("timeout", float, unit="s", default=40.0, doc="fail after this much clock time"),
    ],
    outputs=[
        Output("pose", list, doc="[x, y, theta] localised, map frame [m, m, rad]"),
        Output("spread", list, doc="[position std m, heading std rad] of the estimate"),
        Output("turned", float, doc="how far the base turned [rad]"),
    ],
    needs=("base",),
)
def localize(ctx: SkillContext, force: bool = False, turn_speed: float = 0.6, min_updates: int = 5,
             min_turn: float = 2 * math.pi, timeout: float = 40.0) -> SkillGen:
    """Global localisation, then turn in place at ``turn_speed`` until the localiser has
    converged (at least ``min_updates`` filter updates after the reset, and at least
    ``min_turn`` turned). Succeeds at once
    when already localised (unless ``force``) or when the robot runs no localiser.
    TIMEOUT when not converged within ``timeout``; EXECUTION on a base fault. Turn in a
    place with room: the arm should be stowed."""
    if not (math.isfinite(turn_speed) and turn_speed > 0 and math.isfinite(timeout) and timeout > 0):
        raise SkillFailure(FailureKind.PRECONDITION,
                           f"localize: turn_speed and timeout must be > 0, got {turn_speed:g} rad/s, {timeout:g} s")
    base = ctx.robot.base
    assert base is not None
    st = base.state()
    here = [st.pose.x, st.pose.y, st.pose.theta]
    if not isinstance(base, LocalizingBase):
        ctx.emit("localize", outcome="no_localiser", node=ctx.node_path)
        return {"pose": here, "spread": [0.0, 0.0], "turned": 0.0}
    if st.localised and not force:
        return {"pose": here, "spread": list(spread(st)), "turned": 0.0}
    loc = base.localizer
    loc.global_localisation()
    start_updates = loc.updates
    w_max = min(turn_speed, base.max_angular)
    turned, last_theta = 0.0, base.odometry().pose.theta
    ctx.emit("localize", outcome="started", force=force, node=ctx.node_path)

    def step(state: BaseState, _now: float) -> tuple[float, float] | Step:
        nonlocal turned, last_theta
        th = base.odometry().pose.theta
        turned += abs(math.atan2(math.sin(th - last_theta), math.cos(th - last_theta)))
        last_theta = th
        if state.localised and loc.updates - start_updates >= min_updates and turned >= min_turn:
            return Step.ARRIVED
        return 0.0, w_max

    t_end = ctx.clock.now() + timeout
    yield from motion_loop(ctx, base, step, fault="base fault while localising", deadline=t_end,
                           timeout=f"not localised after {timeout:g} s of turning in place",
                           timeout_kind=FailureKind.TIMEOUT,
                           on_failure=lambda reason: ctx.emit("localize", outcome="failed", reason=reason,
                                                              node=ctx.node_path))
    st = base.state()
    sd = spread(st)
    ctx.emit("localize", outcome="localised", pose=[round(st.pose.x, 3), round(st.pose.y, 3), round(st.pose.theta, 3)],
             spread=[round(sd[0], 4), round(sd[1], 4)], turned=round(turned, 3), updates=loc.updates - start_updates,
             node=ctx.node_path)
    return {"pose": [st.pose.x, st.pose.y, st.pose.theta], "spread": list(sd), "turned": turned}
