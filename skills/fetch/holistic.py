"""The fetch mission's way to a marker whose front is blocked: the holistic planner's
target from the marker estimate, and a second look at the marker from wherever the base
stopped.

Where no stand-off along the marker's normal is free (a box on the floor in front of the
shelf, a corner), ``approach`` fails PLANNING and the approach subtree
(``trees/fetch/approach.yaml``) falls back to ``holistic_standoff``
(:mod:`mmexec.skills.manipulation.holistic_skill`: base x, y, yaw and the arm planned
together to the pick's pre-grasp) as the fetch_object mission does. It needs a grasp
frame in the world model: :func:`marker_grasp_frame` puts the marker's there, in the
holistic convention (z out of the face, towards where the gripper comes from; y up), at
the point the pick grasps: ``fetch.grasp_depth`` behind the face, ``fetch.grasp_height``
up. After the drive, :func:`relocate_marker` looks at the marker again from the pose the
base reached (a pan/tilt head aimed at it first), so the pick plans from a close view
taken where the base stands, not from the search's far one.
"""

from __future__ import annotations

import logging

import numpy as np

from mmexec.skills.base import (
    FailureKind,
    Output,
    Param,
    SkillContext,
    SkillFailure,
    SkillGen,
    skill,
    wait_goal,
)
from mmexec.skills.fetch.profile import fetch_profile
from mmexec.skills.perception.detect import camera_settings, emit_estimate, look, markers

__all__ = ["WORLD_GRASP_FRAME", "marker_grasp_frame", "marker_grasp_transform", "relocate_marker"]

log = logging.getLogger(__name__)

#: world-model key of the requested marker's grasp frame (4x4, ``map``), for
#: ``holistic_standoff``'s ``frame`` parameter
WORLD_GRASP_FRAME = "fetch.grasp_frame"

#: [s] clock time the camera rests after the head moved, before the look
HEAD_SETTLE = 0.3


def marker_grasp_transform(T_map_marker: np.ndarray, grasp_depth: float, grasp_height: float) -> np.ndarray:
    """The grasp frame (4x4, ``map``) of the box behind the marker at ``T_map_marker``:
    the marker's axes (z out of the face, y up: the holistic planner's front-grasp
    convention, :func:`mmexec.skills.manipulation.holistic_skill.grasp_frame`), its
    origin ``grasp_depth`` [m] behind the face and ``grasp_height`` [m] up along the
    marker's y: where the pick's grasp pose puts the grasp point
    (:func:`mmexec.skills.manipulation.grasp.grasp_poses`)."""
    off = np.eye(4)
    off[1, 3], off[2, 3] = grasp_height, -grasp_depth
    return np.asarray(T_map_marker, dtype=float) @ off


@skill(
    "marker_grasp_frame",
    params=[Param("marker", int, required=True, doc="marker id of the item (its estimate is in the world model)")],
    outputs=[
        Output("size", list, doc="[m] the item's box along the grasp frame's x, y, z (holistic_standoff 'size')"),
        Output("object_size", list, doc=(
            "[m] the item's [length, width, height] (holistic_standoff 'object_size': held in the carry posture)")),
        Output("back_off", float, doc="[m] how far the pick backs off before its carry posture (fetch.back_off)"),
    ],
)
def marker_grasp_frame(ctx: SkillContext, marker: int) -> SkillGen:
    """Put the grasp frame of the box behind marker ``marker`` in the world model
    (:data:`WORLD_GRASP_FRAME`, 4x4 in ``map``; :func:`marker_grasp_transform` with the
    profile's ``fetch.grasp_depth`` and ``fetch.grasp_height``) for ``holistic_standoff``,
    and output the item's sizes and the pick's back-off from the profile's ``fetch:``
    section. PRECONDITION when there is no estimate of the marker."""
    est = markers(ctx).get(marker)
    if est is None:
        raise SkillFailure(FailureKind.PRECONDITION, f"marker_grasp_frame: no estimate of marker {marker} (detect it first)")
    prof = fetch_profile(ctx)
    ctx.world[WORLD_GRASP_FRAME] = marker_grasp_transform(est.T_map_marker, prof.grasp_depth, prof.grasp_height)
    sx, sy, sz = (float(v) for v in prof.item_size)
    yield from ()
    # the box behind a marker on its +x face: along the marker's x, y, z it is (sy, sz, sx)
    return {"size": [sy, sz, sx], "object_size": [sx, sy, sz], "back_off": float(prof.back_off)}


@skill(
    "relocate_marker",
    params=[
        Param("marker", int, required=True, doc="marker id"),
        Param("frames", int, doc="frames averaged (default: profile camera.detect_frames)"),
    ],
    outputs=[Output("seen", bool, doc="whether the marker was seen (and its estimate replaced)")],
    needs=("camera",),
)
def relocate_marker(ctx: SkillContext, marker: int, frames: int | None = None) -> SkillGen:
    """Look at marker ``marker`` again from where the base stands (after a holistic
    stand-off: beside the blocker, turned): a pan/tilt head is first aimed at the
    estimate (``Head.look_at``) and goes home afterwards. Seen: the new estimate, from
    this base pose, replaces the old one (event ``marker_estimate``). Not seen (a camera
    that cannot be aimed there, a wrist camera): the old estimate stays (event
    ``marker_not_relocated``). PRECONDITION when there is no estimate at all."""
    est = markers(ctx).get(marker)
    if est is None:
        raise SkillFailure(FailureKind.PRECONDITION, f"relocate_marker: no estimate of marker {marker}")
    n = camera_settings(ctx).detect_frames if frames is None else frames
    head, base = ctx.robot.head, ctx.robot.base
    aimed = False
    if head is not None and base is not None:
        centre = np.append(est.T_map_marker[:3, 3], 1.0)
        in_base = (np.linalg.inv(base.state().pose.matrix()) @ centre)[:3]
        try:
            yield from wait_goal(ctx, head.look_at([float(v) for v in in_base]), timeout=10.0)
            aimed = True
        except SkillFailure as e:
            log.info("relocate_marker: head not aimed at marker %d: %s", marker, e.reason)
        end = ctx.clock.now() + HEAD_SETTLE
        while ctx.clock.now() < end - 1e-9:
            yield
    try:
        new = yield from look(ctx, marker, n)
    except BaseException:
        if aimed and head is not None:
            head.point(*head.home)  # not waited for: cancelled or failed
        raise
    if aimed and head is not None:
        yield from wait_goal(ctx, head.point(*head.home), timeout=10.0)
    if new is None:
        ctx.emit("marker_not_relocated", marker=marker, aimed=aimed, node=ctx.node_path)
        return {"seen": False}
    emit_estimate(ctx, new)
    return {"seen": True}
