"""Multi-frame marker pose averaging with outlier rejection.

Positions are averaged arithmetically, rotations with the quaternion average of
Markley et al. (the eigenvector of the largest eigenvalue of ``sum q q^T``, which is
sign-invariant). Outliers are rejected first against the median position and the
rotation closest to all others (the medoid).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from mmexec.drivers.geometry import matrix_to_quat, quat_to_matrix

__all__ = [
    "MarkerPoseEstimator",
    "PoseEstimate",
    "average_poses",
    "rotation_angle",
]


def rotation_angle(Ra: np.ndarray, Rb: np.ndarray) -> float:
    """Angle [rad] of the rotation taking ``Ra`` to ``Rb``."""
    c = (np.trace(np.asarray(Ra).T @ np.asarray(Rb)) - 1.0) / 2.0
    return math.acos(max(-1.0, min(1.0, c)))


@dataclass(frozen=True)
class PoseEstimate:
    """Averaged pose ``T`` (4x4, same frames as the inputs), how many inputs were used and
    rejected, and the spread of the used positions (RMS distance to the mean) [m]."""

    T: np.ndarray
    used: int
    rejected: int
    position_spread: float


def average_poses(
    poses: Sequence[np.ndarray],
    *,
    max_position_dev: float = 0.03,
    max_angle_dev: float = math.radians(10.0),
) -> PoseEstimate:
    """Average 4x4 poses, dropping those further than ``max_position_dev`` [m] from the
    median position or ``max_angle_dev`` [rad] from the medoid rotation. Raises
    ValueError when given nothing; when everything would be rejected the medoid alone
    is returned (used = 1)."""
    if not poses:
        raise ValueError("average_poses: no poses")
    Ts = [np.asarray(T, dtype=float) for T in poses]
    P = np.array([T[:3, 3] for T in Ts])
    med = np.median(P, axis=0)
    n = len(Ts)
    if n > 2:
        ang = np.array([[rotation_angle(Ts[i][:3, :3], Ts[j][:3, :3]) for j in range(n)] for i in range(n)])
        medoid = int(np.argmin(np.sum(ang, axis=1)))
    else:
        medoid = 0
    keep = [
        i for i in range(n)
        if np.linalg.norm(P[i] - med) <= max_position_dev
        and rotation_angle(Ts[i][:3, :3], Ts[medoid][:3, :3]) <= max_angle_dev
    ]
    if not keep:
        keep = [medoid]
    pos = P[keep].mean(axis=0)
    M = np.zeros((4, 4))
    for i in keep:
        q = matrix_to_quat(Ts[i][:3, :3])
        M += np.outer(q, q)
    w, V = np.linalg.eigh(M)
    q_mean = V[:, int(np.argmax(w))]
    T = np.eye(4)
    T[:3, :3] = quat_to_matrix(q_mean)
    T[:3, 3] = pos
    spread = float(np.sqrt(np.mean(np.sum((P[keep] - pos) ** 2, axis=1))))
    return PoseEstimate(T=T, used=len(keep), rejected=n - len(keep), position_spread=spread)


class MarkerPoseEstimator:
    """Collects ``T_map_marker`` observations of one marker over frames and averages them.

    ``add(T)`` each frame the marker is seen; ``ready`` once ``min_samples`` were added;
    ``estimate()`` averages the last ``window`` samples (see :func:`average_poses`).
    """

    def __init__(
        self,
        min_samples: int = 3,
        window: int = 10,
        max_position_dev: float = 0.03,
        max_angle_dev: float = math.radians(10.0),
    ) -> None:
        if min_samples < 1 or window < min_samples:
            raise ValueError(f"need 1 <= min_samples <= window (got {min_samples}, {window})")
        self.min_samples = min_samples
        self.window = window
        self.max_position_dev = max_position_dev
        self.max_angle_dev = max_angle_dev
        self._samples: list[np.ndarray] = []

    def add(self, T_map_marker: np.ndarray) -> None:
        self._samples.append(np.asarray(T_map_marker, dtype=float).copy())
        if len(self._samples) > self.window:
            self._samples.pop(0)

    @property
    def count(self) -> int:
        return len(self._samples)

    @property
    def ready(self) -> bool:
        return len(self._samples) >= self.min_samples

    def estimate(self) -> PoseEstimate:
        """The averaged pose; raises ValueError when nothing was added."""
        return average_poses(
            self._samples, max_position_dev=self.max_position_dev, max_angle_dev=self.max_angle_dev
        )

    def clear(self) -> None:
        self._samples.clear()
