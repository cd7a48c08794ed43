"""Grasp candidates around a sphere's barycentre (thesis Algorithm 1.1) and the choice
among the reachable ones.

The thesis (ros2-thesis-follower-buttons-fruit, section 1.3.2) grasps balls and apples
with a soft gripper on an Igus Rebel, planned with MoveIt 2. From the barycentre ``p``
(Algorithm 1.2, :mod:`mmexec.skills.perception.sphere`) moved into the arm base frame it
makes 50 candidate end-effector poses with ``theta`` in ``linspace(-pi, pi/3, 50)`` on
the vertical plane through the arm base and ``p``, each at the grasp distance ``g``
(0.05 m) from ``p`` and facing it; keeps those for which an inverse kinematics solution
exists; and picks the one at a quarter of the kept list ("the first candidates grasp
from the top, the last from the bottom"; near the top is easier to reach for an arm on
a mobile base). Here the candidates are pure geometry (:func:`grasp_candidates`) and the
choice takes any reachability callback (:func:`select_grasp`), so our IK with a
collision check (:meth:`ArmKinematics.ik` with ``is_valid``) or the planner plugs in.

Our reading of the algorithm (its printed text is partly garbled):

* ``v_c = p / |p|`` (base to barycentre), ``p_v`` the horizontal unit vector towards
  ``p``; "the vertical component" ``v_v = (v_c x p_v) x v_c`` equals
  ``p_v - (p_v . v_c) v_c``: the direction in the vertical plane perpendicular to
  ``v_c``. As printed its length is ``|sin(elevation of p)|``, so it vanishes for an
  object at the height of the arm base, and it turns upwards for objects below that
  height. We keep the intent, a unit vector ``v_perp`` in the plane perpendicular to
  ``v_c``, with the printed direction for objects above the base (downwards and away
  from the base: ``v_perp = n x v_c`` with ``n = z x p_v``) and no flip or collapse.
* ``v_l = -g cos(theta) v_c`` and ``v_v = g sin(theta) v_perp``; the printed
  ``v_grasp = v_v + v_l + v_c`` mixes a unit vector with the offsets: we read the grasp
  position as ``p + v_l + v_v`` (the tool origin at ``g`` from the barycentre) and the
  tool's approach axis as ``-(v_l + v_v) / g``, i.e. from the tool towards ``p``:
  ``a(theta) = cos(theta) v_c - sin(theta) v_perp``. So ``theta = 0`` approaches along
  ``v_c`` (from the base side), ``-pi/2`` straight down along ``v_perp`` (from the top),
  ``pi/3`` from below at 60 degrees, ``-pi`` from behind the object towards the base
  (rarely reachable: the kept list then starts near the top, as the thesis says).
* the printed orientation is ``y = (0, 0, 1) x x`` and ``z = x x y``: ``y`` horizontal,
  perpendicular to the plane. Its sign flips where the approach passes the vertical (and
  it is zero there); we take ``y = n`` for every candidate, which is the printed ``y``
  wherever the approach points away from the base. For a tool approaching along z (UR +
  Robotiq) the same frame is laid out as ``x = up``, ``y = -n``, ``z = approach``, the
  convention of :func:`~mmexec.skills.manipulation.grasp.tool_rotation_in_marker`.

Where we differ: the thesis' ``g = 0.05`` m is the soft gripper's distance from the
fruit's centre to its tool frame. Our parallel grippers' tool frames are between the
finger pads (WX250s ``ee_gripper_link``; the UR TCP at the 2F-85's closed-grasp point),
so the default ``distance`` is 0: the pads close across the sphere's centre; set it to
0.05 for the thesis' poses. The pre-grasp pose (Algorithm 1.3's ``G'``) is the grasp
pose moved back along the approach by ``pre_grasp_distance``.

Frames: the barycentre and every pose are in the arm base frame (x forward, z up), 4x4
``T_armbase_tool``; m, rad.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

__all__ = [
    "CandidateConfig",
    "GraspCandidates",
    "GraspChoice",
    "grasp_candidates",
    "select_grasp",
]

log = logging.getLogger(__name__)

#: Reachability of one tool pose: joint positions [rad] when a (collision-free) IK
#: solution exists, else None.
Reachability = Callable[[np.ndarray], np.ndarray | None]


@dataclass(frozen=True)
class CandidateConfig:
    """Algorithm 1.1's settings: ``count`` candidates with ``theta`` [rad] evenly over
    ``theta_range`` (ends included); ``distance`` [m] from the barycentre to the tool
    origin (thesis: 0.05 for its soft gripper; 0 for a parallel gripper whose tool frame
    is between the pads); ``pre_grasp_distance`` [m] further back along the approach for
    the pre-grasp; ``pick_fraction``: the chosen candidate's position in the list of
    reachable ones (thesis: a quarter)."""

    count: int = 50
    theta_range: tuple[float, float] = (-math.pi, math.pi / 3)
    distance: float = 0.0
    pre_grasp_distance: float = 0.10
    pick_fraction: float = 0.25

    def validate(self) -> list[str]:
        errs = []
        if self.count < 1:
            errs.append(f"count: must be >= 1, got {self.count}")
        lo, hi = self.theta_range
        if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
            errs.append(f"theta_range: must be finite with min <= max rad, got {self.theta_range}")
        if not self.distance >= 0:
            errs.append(f"distance: must be >= 0 m, got {self.distance}")
        if not self.pre_grasp_distance >= 0:
            errs.append(f"pre_grasp_distance: must be >= 0 m, got {self.pre_grasp_distance}")
        if not 0 <= self.pick_fraction < 1:
            errs.append(f"pick_fraction: must be in [0, 1), got {self.pick_fraction}")
        return errs


@dataclass(frozen=True)
class GraspCandidates:
    """``thetas`` (n,) [rad]; ``poses`` and ``pre_grasps`` (n, 4, 4) tool poses in the arm
    base frame; ``approach`` (n, 3) unit approach directions (tool towards the
    barycentre); ``barycentre`` (3,) [m]; ``approach_axis`` the tool axis that approaches
    (0 = x, 2 = z)."""

    thetas: np.ndarray
    poses: np.ndarray
    pre_grasps: np.ndarray
    approach: np.ndarray
    barycentre: np.ndarray
    approach_axis: int

    def __len__(self) -> int:
        return len(self.thetas)


@dataclass(frozen=True)
class GraspChoice:
    """The chosen candidate: ``index`` into the candidates, its ``theta`` [rad], ``pose``
    and ``pre_grasp`` (4x4), the callback's ``solution`` (joint positions [rad]) and the
    indices of all ``feasible`` candidates in list order."""

    index: int
    theta: float
    pose: np.ndarray
    pre_grasp: np.ndarray
    solution: np.ndarray
    feasible: tuple[int, ...]


def grasp_candidates(barycentre: Sequence[float] | np.ndarray, approach_axis: int,
                     config: CandidateConfig | None = None) -> GraspCandidates:
    """The candidate tool poses of Algorithm 1.1 around ``barycentre`` (3,) [m, arm base
    frame], for a tool approaching along its x (``approach_axis`` 0, WX250s) or z (2, UR).
    Raises ValueError for a barycentre on the base's vertical axis (no vertical plane
    through both) or bad settings."""
    cfg = config or CandidateConfig()
    errs = cfg.validate()
    if approach_axis not in (0, 2):
        errs.append(f"approach_axis: must be 0 (x) or 2 (z), got {approach_axis}")
    if errs:
        raise ValueError("grasp candidates: " + "; ".join(errs))
    p = np.asarray(barycentre, dtype=float).reshape(3)
    horiz = math.hypot(p[0], p[1])
    if not np.all(np.isfinite(p)) or horiz < 1e-6:
        raise ValueError(f"grasp candidates: barycentre {p.tolist()} m is on the arm base's vertical axis "
                         "(or not finite): no vertical plane through both")
    v_c = p / np.linalg.norm(p)
    n = np.array([-p[1], p[0], 0.0]) / horiz            # z x p_v: the plane's horizontal normal
    v_perp = np.cross(n, v_c)                            # in the plane, perpendicular to v_c, down
    thetas = np.linspace(cfg.theta_range[0], cfg.theta_range[1], cfg.count)
    a = np.cos(thetas)[:, None] * v_c - np.sin(thetas)[:, None] * v_perp   # (k, 3) approach
    up = np.cross(a, n)                                  # tool "up": in the plane, perpendicular to a
    R = np.empty((len(thetas), 3, 3))
    if approach_axis == 0:
        R[:, :, 0], R[:, :, 1], R[:, :, 2] = a, n, up
    else:
        R[:, :, 0], R[:, :, 1], R[:, :, 2] = up, -n, a
    poses = np.tile(np.eye(4), (len(thetas), 1, 1))
    poses[:, :3, :3] = R
    poses[:, :3, 3] = p - cfg.distance * a
    pre = poses.copy()
    pre[:, :3, 3] -= cfg.pre_grasp_distance * a
    return GraspCandidates(thetas, poses, pre, a, p, approach_axis)


def select_grasp(candidates: GraspCandidates, reachable: Reachability,
                 pick_fraction: float = 0.25) -> GraspChoice | None:
    """Keep the candidates for which ``reachable(pose)`` gives a joint solution, in list
    order, and choose the one at ``pick_fraction`` of the kept list (index
    ``floor(fraction * kept)``); None when none is reachable."""
    if not 0 <= pick_fraction < 1:
        raise ValueError(f"pick_fraction: must be in [0, 1), got {pick_fraction}")
    feasible: list[int] = []
    solutions: list[np.ndarray] = []
    for i, T in enumerate(candidates.poses):
        q = reachable(T)
        if q is not None:
            feasible.append(i)
            solutions.append(np.asarray(q, dtype=float))
    log.debug("grasp candidates: %d of %d reachable", len(feasible), len(candidates))
    if not feasible:
        return None
    k = int(pick_fraction * len(feasible))
    i = feasible[k]
    return GraspChoice(i, float(candidates.thetas[i]), candidates.poses[i].copy(), candidates.pre_grasps[i].copy(),
                       solutions[k], tuple(feasible))
