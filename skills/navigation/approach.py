"""The ``approach`` skill: drive to a stand-off pose in front of a marker, facing it, at a
distance the mission picks from the profile's list (``nav.approach_distances``; the
fetch mission's recovery indexes it). A marker seen from afar is looked at again on the
way (``nav.refine_at``), and once more from the stand-off when ``nav.redetect_at_standoff``
is set, so a pick plans from the closest estimate.

Base motion is :func:`mmexec.skills.navigation.navigate.drive_path` (``base_status``
events); the marker comes from the world model (:func:`mmexec.skills.perception.detect.markers`).
"""

from __future__ import annotations

import logging
import math

from mmexec.skills.base import (
    FailureKind,
    Output,
    Param,
    SkillContext,
    SkillFailure,
    SkillGen,
    skill,
)
from mmexec.skills.navigation import find_standoff, simplify_path
from mmexec.skills.navigation.navigate import (
    REFINE_SHORT,
    base_status,
    costmap,
    drive_path,
    nav_settings,
)
from mmexec.skills.perception.detect import camera_settings, emit_estimate, look, markers

__all__ = ["approach"]

log = logging.getLogger(__name__)


@skill(
    "approach",
    params=[
        Param("marker", int, required=True, doc="marker id whose estimate (world model) to approach"),
        Param("distance", float, unit="m", doc="stand-off from the marker face along its normal"),
        Param("distance_index", int, default=0,
              doc="when 'distance' is not given: index into the profile's approach_distances "
                  "(clamped to the last one); the mission passes the recovery counter"),
        Param("timeout", float, unit="s", doc="fail after this much clock time"),
        Param("refine_from", float, unit="m", default=0.95,
              doc="when the estimate was seen from farther than this, re-estimate it on the way"),
        Param("refine_at", float, unit="m",
              doc="stand-off distance of that intermediate viewpoint (default: profile nav.refine_at)"),
    ],
    outputs=[
        Output("pose", list, doc="[x, y, theta] reached, map frame"),
        Output("distance", float, doc="stand-off distance used [m]"),
    ],
    needs=("base",),
)
def approach(ctx: SkillContext, marker: int, distance: float | None = None, distance_index: int = 0,
             timeout: float | None = None, refine_from: float = 0.95,
             refine_at: float | None = None) -> SkillGen:
    """Reach a stand-off pose at ``distance`` from the marker along its outward normal,
    facing it (small angular offsets around the normal are tried when the straight one
    is blocked). PLANNING failure when no stand-off is free or reachable."""
    est = markers(ctx).get(marker)
    if est is None:
        raise SkillFailure(FailureKind.PRECONDITION, f"approach: no estimate of marker {marker} (search for it first)")
    prof = nav_settings(ctx)
    if distance is None:
        if distance_index < 0:
            raise SkillFailure(FailureKind.PRECONDITION, f"approach: distance_index must be >= 0, got {distance_index}")
        distance = prof.approach_distances[min(distance_index, len(prof.approach_distances) - 1)]
    if distance <= 0:
        raise SkillFailure(FailureKind.PRECONDITION, f"approach: distance must be > 0 m, got {distance:g}")
    base = ctx.robot.base
    assert base is not None
    cm = costmap(ctx)
    limit = timeout if timeout is not None else prof.timeout
    if refine_at is None:
        refine_at = prof.refine_at
    if est.distance > refine_from and ctx.robot.camera is not None:
        # a marker's orientation seen from afar is poor (degrees of error at 1.5 m): stop
        # at an intermediate stand-off on the way, look again, then aim at the final one
        mid = find_standoff(cm, est.T_map_marker, [refine_at, refine_at + 0.2],
                            angle_offsets=(0.0,), start=(base.state().pose.x, base.state().pose.y))
        if mid.ok and mid.pose is not None:
            yield from drive_path(ctx, mid.pose, f"marker {marker} viewpoint", timeout=limit,
                                  path=simplify_path(cm, mid.path) if mid.path else None, viewpoint=True,
                                  view_short=REFINE_SHORT)
            better = yield from look(ctx, marker, camera_settings(ctx).detect_frames)
            if better is not None:
                est = better
    start = base.state().pose
    found = find_standoff(cm, est.T_map_marker, [distance],
                          angle_offsets=(0.0, math.radians(10), -math.radians(10)), start=(start.x, start.y))
    if not found.ok or found.pose is None:
        base_status(ctx, "goal_fail", reason=found.reason or "no stand-off", marker=marker, distance=distance)
        base_status(ctx, "idle")
        why = "no free stand-off" if all(t[2] != "no path from start" for t in found.tried) else "no path"
        raise SkillFailure(FailureKind.PLANNING,
                           f"no path to the stand-off {distance:.2f} m from marker {marker}: {why}")
    ctx.emit("standoff", marker=marker, distance=distance, pose=[round(found.pose.x, 3), round(found.pose.y, 3),
                                                                round(found.pose.theta, 3)], node=ctx.node_path)
    path = simplify_path(cm, found.path) if found.path else None
    reached = yield from drive_path(ctx, found.pose, f"marker {marker} stand-off", timeout=limit, path=path)
    if prof.redetect_at_standoff and ctx.robot.camera is not None:
        # the closest view before the pick: the grasp is planned from this estimate
        near = yield from look(ctx, marker, camera_settings(ctx).detect_frames)
        if near is None:
            log.warning("marker %d not in view from its stand-off; the pick uses the estimate from %.2f m",
                        marker, est.distance)
        else:
            emit_estimate(ctx, near)
    return {"pose": [reached.x, reached.y, reached.theta], "distance": distance}
