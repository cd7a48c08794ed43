"""The seed paper's pick and place poses, as tool poses in the marker (or place) frame.

Marker frame (OpenCV ArUco, as produced by :mod:`mmexec.skills.perception`): origin at
the marker centre, x right and y up as printed, z out of the printed face towards the
robot. The seed paper uses ARTag (ar_track_alvar) frames, which follow the same
convention: z is the outward normal of the tag, and its offsets are "along the Z-axis of
the ARTag frame" for the pre-grasp.

Seed offsets (positions of the tool frame origin in the marker frame, metres):

* pre-grasp ``(0, 0, 0.10)``: 10 cm in front of the face;
* grasp: at the marker (``grasp_depth`` metres behind the face, default 0) with the
  gripper's approach axis pointing into the face (along -z of the marker);
* retract after the grasp ``(0, -0.10, 0.10)``. Note: the seed paper's text says
  "10 cm away along the X-axis and 10 cm higher" while its equation gives
  ``[0, -0.1, 0.1]`` and its figure caption says "along the Z-axis and the X-axis"; the
  three disagree. We keep the equation's vector as the default (with the marker's y up,
  that is 10 cm out and 10 cm *down*) and make it a parameter: pass
  ``retract=(0, 0.10, 0.10)`` for out-and-up.
* place: the place frame (a marker-like frame at the depot, z towards the robot) with
  the same tool orientation; retract after placing ``(0, 0, 0.10)``.

Grasp height: ``grasp_height`` [m] moves every pose of the pick (pre-grasp, grasp,
retract) and of the place along the marker's y (up), so the approach stays a straight
line along the face normal and the item is released with its centre where it was asked
for. A gripper whose body, seen along the approach, reaches lower than half the box
height (a Robotiq 2F-85: a 65 mm thick body and a 75 mm coupling against a 60 mm box)
would drive into the board the box stands on when grasping at the box centre; raised by
``grasp_height`` it closes its horizontal fingers on the upper part of the box's side
faces and its body clears the board. 0 grasps at the marker centre (the seed's poses).

Tool frames: the WX250s ``ee_gripper_link`` approaches along its x axis with the fingers
moving along y; the UR TCP approaches along z with the Robotiq fingers along y. The
orientation chosen puts the finger travel horizontal (along the marker's x) so the
fingers close on the box's side faces, and the tool's "up" along the marker's y.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = [
    "GraspPoses",
    "PlacePoses",
    "grasp_poses",
    "place_poses",
    "tool_rotation_in_marker",
]


def tool_rotation_in_marker(approach_axis: int) -> np.ndarray:
    """3x3 rotation ``R_marker_tool`` for a gripper approaching the marker face.

    ``approach_axis`` 0 (tool x approaches, WX250s): tool x = -z_m, y = -x_m, z = y_m.
    ``approach_axis`` 2 (tool z approaches, UR + Robotiq): tool x = y_m, y = x_m, z = -z_m.
    """
    if approach_axis == 0:
        cols = ([0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    elif approach_axis == 2:
        cols = ([0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0])
    else:
        raise ValueError(f"approach_axis must be 0 (x) or 2 (z), got {approach_axis}")
    R = np.array(cols, dtype=float).T
    return R


def _pose(R: np.ndarray, t: Sequence[float]) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return T


@dataclass(frozen=True)
class GraspPoses:
    """Tool poses (4x4) in the frame the inputs were in (``map`` if given ``T_map_marker``)."""

    pre_grasp: np.ndarray
    grasp: np.ndarray
    retract: np.ndarray


@dataclass(frozen=True)
class PlacePoses:
    place: np.ndarray
    retract: np.ndarray


def grasp_poses(
    T_frame_marker: np.ndarray,
    approach_axis: int,
    *,
    pre_grasp: Sequence[float] = (0.0, 0.0, 0.10),
    grasp_depth: float = 0.0,
    retract: Sequence[float] = (0.0, -0.10, 0.10),
    grasp_height: float = 0.0,
) -> GraspPoses:
    """Pre-grasp, grasp and retract tool poses for the marker at ``T_frame_marker`` (any
    parent frame: map, arm base). Offsets in metres in the marker frame; ``grasp_depth``
    [m] moves the grasp point behind the face (into the box); ``grasp_height`` [m] moves
    all three poses along the marker's y (up)."""
    T_fm = np.asarray(T_frame_marker, dtype=float)
    R = tool_rotation_in_marker(approach_axis)
    up = np.array([0.0, grasp_height, 0.0])
    return GraspPoses(
        pre_grasp=T_fm @ _pose(R, np.asarray(pre_grasp, dtype=float) + up),
        grasp=T_fm @ _pose(R, np.array([0.0, 0.0, -grasp_depth]) + up),
        retract=T_fm @ _pose(R, np.asarray(retract, dtype=float) + up),
    )


def place_poses(
    T_frame_place: np.ndarray,
    approach_axis: int,
    *,
    retract: Sequence[float] = (0.0, 0.0, 0.10),
    grasp_height: float = 0.0,
) -> PlacePoses:
    """Place and post-place retract tool poses for the place frame ``T_frame_place``
    (marker convention: z towards the robot). ``grasp_height`` [m]: how far above the
    item's centre it was grasped; both poses move up by it, so the item's centre is
    released at the place frame's origin."""
    T_fp = np.asarray(T_frame_place, dtype=float)
    R = tool_rotation_in_marker(approach_axis)
    up = np.array([0.0, grasp_height, 0.0])
    return PlacePoses(place=T_fp @ _pose(R, up), retract=T_fp @ _pose(R, np.asarray(retract, dtype=float) + up))
