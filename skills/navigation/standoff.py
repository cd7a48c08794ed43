"""Stand-off poses: where the base should stop to face a marker from a given distance.

The marker pose is ``T_map_marker`` in the OpenCV ArUco convention used by
:mod:`mmexec.skills.perception`: origin at the marker centre, x right, y up as printed,
z out of the printed face towards whoever can see it (the outward normal).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from mmexec.drivers.interfaces import Pose2D
from mmexec.skills.navigation.astar import plan_path
from mmexec.skills.navigation.grid import CostMap

__all__ = ["StandoffResult", "find_standoff", "marker_normal_2d", "standoff_pose"]


def marker_normal_2d(T_map_marker: np.ndarray) -> tuple[float, float]:
    """Unit outward normal of the marker projected on the floor plane (map x, y).

    Raises ValueError when the marker faces straight up or down (no horizontal normal).
    """
    n = np.asarray(T_map_marker, dtype=float)[:3, 2]
    h = math.hypot(n[0], n[1])
    if h < 1e-3:
        raise ValueError("marker normal is vertical: no horizontal stand-off direction")
    return float(n[0] / h), float(n[1] / h)


def standoff_pose(T_map_marker: np.ndarray, distance: float, angle_offset: float = 0.0) -> Pose2D:
    """Base pose [m, rad] in ``map`` at ``distance`` [m] from the marker along its outward
    normal (rotated by ``angle_offset`` [rad] about the vertical through the marker),
    facing the marker."""
    nx, ny = marker_normal_2d(T_map_marker)
    c, s = math.cos(angle_offset), math.sin(angle_offset)
    nx, ny = c * nx - s * ny, s * nx + c * ny
    mx, my = float(T_map_marker[0, 3]), float(T_map_marker[1, 3])
    return Pose2D(mx + distance * nx, my + distance * ny, math.atan2(-ny, -nx))


@dataclass(frozen=True)
class StandoffResult:
    """Outcome of :func:`find_standoff`: ``pose`` (None when none fits), ``path`` from the
    start when one was asked for, ``reason`` (empty on success) and every tried
    ``(distance, angle_offset, why_rejected)``."""

    pose: Pose2D | None
    path: list[tuple[float, float]] | None = None
    reason: str = ""
    tried: list[tuple[float, float, str]] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return self.pose is not None


def find_standoff(
    costmap: CostMap,
    T_map_marker: np.ndarray,
    distances: Sequence[float],
    *,
    angle_offsets: Sequence[float] = (0.0, math.radians(15), -math.radians(15), math.radians(30), -math.radians(30)),
    start: tuple[float, float] | None = None,
) -> StandoffResult:
    """First free stand-off pose, trying each distance [m] in order and, per distance, each
    angular offset [rad] around the marker normal. With ``start`` (map point [m]) a pose
    counts only if A* finds a path to it, which is returned too."""
    tried: list[tuple[float, float, str]] = []
    try:
        marker_normal_2d(T_map_marker)
    except ValueError as e:
        return StandoffResult(None, None, str(e), tried)
    for d in distances:
        for a in angle_offsets:
            pose = standoff_pose(T_map_marker, d, a)
            if not costmap.is_free(pose.x, pose.y):
                tried.append((d, a, "pose in collision or off the map"))
                continue
            if start is not None:
                path = plan_path(costmap, start, (pose.x, pose.y))
                if path is None:
                    tried.append((d, a, "no path from start"))
                    continue
                return StandoffResult(pose, path, "", tried)
            return StandoffResult(pose, None, "", tried)
    ds = ", ".join(f"{d:.2f}" for d in distances)
    return StandoffResult(None, None, f"no free stand-off at distances [{ds}] m around the marker normal", tried)
