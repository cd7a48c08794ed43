"""An arm's kinematic chain as data: space screws at the zero pose, the tool pose, limits.

Frames: everything is in the arm's mount frame (``arm_base`` of
:mod:`mmexec.drivers.interfaces`: x forward, z up), the tool pose is ``T_armbase_tool``
of the description's tool link (:attr:`ModelInfo.tool_link
<mmexec.drivers.descriptions.model_info.ModelInfo.tool_link>`). Units: m, rad.

Product of exponentials (Lynch and Park, Modern Robotics, chapter 4): joint ``i`` moves
about the unit screw ``S_i = (omega_i; v_i)`` (space frame, zero pose, ``v_i = -omega_i x
q_i`` for a point ``q_i`` on the axis), and ``T(q) = exp([S_1] q_1) ... exp([S_n] q_n) M``.
:func:`dh_to_poe` converts a standard Denavit-Hartenberg table into that form.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from mmexec.drivers.interfaces import JointLimit

__all__ = ["ArmChain", "dh_to_poe", "dh_transform"]


def dh_transform(theta: float, d: float, a: float, alpha: float) -> np.ndarray:
    """4x4 transform of one standard DH row: rotate ``theta`` [rad] about z, move ``d``
    [m] along z, ``a`` [m] along the new x, rotate ``alpha`` [rad] about it."""
    ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
    return np.array([[ct, -st * ca, st * sa, a * ct], [st, ct * ca, -ct * sa, a * st], [0, sa, ca, d], [0, 0, 0, 1.0]])


def dh_to_poe(dh: Sequence[tuple[float, float, float]]) -> tuple[np.ndarray, np.ndarray]:
    """Standard DH rows ``(d, a, alpha)`` [m, m, rad] of revolute joints -> (6xn space
    screws, ``M`` the last DH frame at the zero pose), both in the DH base frame."""
    T = np.eye(4)
    screws = []
    for d, a, alpha in dh:
        w = T[:3, 2].copy()
        p = T[:3, 3].copy()
        screws.append(np.concatenate([w, -np.cross(w, p)]))
        T = T @ dh_transform(0.0, d, a, alpha)
    return np.array(screws).T, T


@dataclass(frozen=True, eq=False)
class ArmChain:
    """A serial arm in product-of-exponentials form (see the module doc).

    ``screws``: 6xn space screw axes (omega; v) at the zero pose; ``M``: 4x4
    ``T_armbase_tool`` at the zero pose; ``limits``: one per joint, in chain order
    (``acceleration`` infinite: see ``acceleration``); ``approach_axis``: the tool
    axis pointing out of the gripper (0 = x, 2 = z); ``tcp_offset`` [m]: the grasp
    point's distance from the tool frame along that axis (0: the tool frame is the grasp
    point); ``acceleration`` [rad/s^2]: the per-joint acceleration used for trajectory
    timing when nothing else is configured (vendors do not publish one).

    The arrays are read-only; compare chains by ``name``.
    """

    name: str
    joint_names: tuple[str, ...]
    screws: np.ndarray
    M: np.ndarray
    limits: tuple[JointLimit, ...]
    approach_axis: int
    tcp_offset: float
    acceleration: float

    def __post_init__(self) -> None:
        n = len(self.joint_names)
        if self.screws.shape != (6, n) or self.M.shape != (4, 4):
            raise ValueError(f"arm chain {self.name}: screws must be 6x{n} and M 4x4, "
                             f"got {self.screws.shape} and {self.M.shape}")
        if tuple(lim.name for lim in self.limits) != self.joint_names:
            raise ValueError(f"arm chain {self.name}: limits {[lim.name for lim in self.limits]} "
                             f"are not for the joints {list(self.joint_names)}")
        if self.approach_axis not in (0, 1, 2):
            raise ValueError(f"arm chain {self.name}: approach_axis must be 0, 1 or 2, got {self.approach_axis}")
        self.screws.flags.writeable = False
        self.M.flags.writeable = False

    @property
    def dof(self) -> int:
        """Number of joints."""
        return len(self.joint_names)
