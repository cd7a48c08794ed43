"""Which detected object to pick first: the thesis' priority score (Algorithm 1.3).

The thesis (ros2-thesis-follower-buttons-fruit, section 1.3.5, Algorithm 1.3 lines
6-13) segments each detected object's point cloud (Algorithm 1.2), takes the distance
``z`` of its centroid, and scores ``s = c / 4 + 3/4 (z_max - z) / z_max`` with ``c`` the
detector's confidence and ``z_max = 1.5`` m; the object with the highest score is picked.
Nearness weighs three times the confidence. We take ``z`` as the centroid's depth along
the camera's optical axis, the same ``z`` Algorithm 1.2 cuts at ``d_max = 1.5`` m, and
leave out objects with no depth or at ``z >= z_max`` (the thesis never sees them: their
points are cut); the score itself is the thesis' formula.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["Z_MAX", "centroid_depth", "choose_target", "priority_scores"]

#: the thesis' maximum object distance [m]
Z_MAX = 1.5


def priority_scores(confidence: Sequence[float] | np.ndarray, distance: Sequence[float] | np.ndarray,
                    z_max: float = Z_MAX) -> np.ndarray:
    """``s = c/4 + 3/4 (z_max - z)/z_max`` per object: ``confidence`` in [0, 1],
    ``distance`` [m]; arrays of one length (or broadcastable)."""
    if not z_max > 0:
        raise ValueError(f"z_max: must be > 0 m, got {z_max}")
    c = np.asarray(confidence, dtype=float)
    z = np.asarray(distance, dtype=float)
    return 0.25 * c + 0.75 * (z_max - z) / z_max


def choose_target(confidence: Sequence[float] | np.ndarray, distance: Sequence[float] | np.ndarray,
                  z_max: float = Z_MAX) -> int | None:
    """Index of the object with the highest :func:`priority_scores` among those with a
    finite ``distance`` in (0, ``z_max``) [m]; None when there is none. Ties go to the
    first."""
    s = priority_scores(confidence, distance, z_max)
    z = np.broadcast_to(np.asarray(distance, dtype=float), s.shape)
    ok = np.isfinite(z) & (z > 0) & (z < z_max) & np.isfinite(s)
    if not np.any(ok):
        return None
    return int(np.argmax(np.where(ok, s, -np.inf)))


def centroid_depth(points: np.ndarray) -> float:
    """Depth [m] of the centroid of an object's points (N, 3) in the camera optical frame
    (its z; Algorithm 1.3 lines 8-9); nan for no points."""
    P = np.asarray(points, dtype=float).reshape(-1, 3)
    return float(P[:, 2].mean()) if len(P) else float("nan")
