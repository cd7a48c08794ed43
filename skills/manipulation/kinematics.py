"""Forward and inverse kinematics of an arm, in product-of-exponentials form.

Frames: every pose is in the arm's mount frame (``arm_base`` in
:mod:`mmexec.drivers.interfaces`: ``arm_base_link`` on the LoCoBot, ROS ``base_link`` of
the UR, x forward, z up), as a 4x4 ``T_armbase_tool``. Units: m, rad.

The arm comes from the robot's description (:attr:`RobotDescription.arm
<mmexec.drivers.descriptions.RobotDescription.arm>`: screws, tool pose, limits, approach
axis and grasp point, see :mod:`mmexec.drivers.descriptions.chain`):
:meth:`ArmKinematics.from_description`. :func:`wx250s` and :func:`ur5e` build the two
arms the descriptions hold today directly (for tests and benchmarks):

* WX250s (LoCoBot variant): the Interbotix PoE parameters (docs/robots.md 1.3) with every
  height lowered by 0.005825 m; tool frame ``ee_gripper_link`` (between the finger pads,
  x = approach direction out of the gripper, y = finger travel, z up at zero pose).
* UR5e: the official DH table (docs/robots.md 2.1), converted to PoE and rotated by pi about
  z so the base is ROS ``base_link`` (the controller's ``base`` frame is x/y flipped);
  tool frame ``tool0`` (z out of the flange) plus a TCP offset along tool z (default
  0.155 m: the Robotiq 2F-85's closed-grasp point), so z is the approach direction.

IK is damped least squares over several seeds (the caller's seed first, then random
configurations from a seeded generator, so results are deterministic), clamped to the
joint limits; it returns None when no seed converges.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from mmexec.drivers.descriptions import ArmChain, RobotDescription, ur5e_robotiq
from mmexec.drivers.descriptions import ur as ur_arm
from mmexec.drivers.descriptions import wx250s as wx250s_arm
from mmexec.drivers.descriptions.chain import dh_to_poe, dh_transform
from mmexec.drivers.interfaces import JointLimit

__all__ = [
    "ArmKinematics",
    "dh_to_poe",
    "exp6",
    "log_so3",
    "skew",
    "ur5e",
    "wx250s",
]


def skew(w: Sequence[float]) -> np.ndarray:
    """3x3 matrix of ``w x``."""
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def exp6(S: np.ndarray, theta: float) -> np.ndarray:
    """4x4 ``exp([S] theta)`` of a unit screw ``S = (omega, v)`` (revolute: |omega| = 1)."""
    w, v = S[:3], S[3:]
    T = np.eye(4)
    W = skew(w)
    s, c = math.sin(theta), math.cos(theta)
    R = np.eye(3) + s * W + (1.0 - c) * (W @ W)
    T[:3, :3] = R
    T[:3, 3] = (np.eye(3) * theta + (1.0 - c) * W + (theta - s) * (W @ W)) @ v
    return T


def log_so3(R: np.ndarray) -> np.ndarray:
    """Rotation vector (axis * angle) [rad] of a 3x3 rotation matrix."""
    c = max(-1.0, min(1.0, (np.trace(R) - 1.0) / 2.0))
    ang = math.acos(c)
    if ang < 1e-9:
        return np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / 2.0
    if math.pi - ang < 1e-6:
        # near pi: axis from the symmetric part
        B = (R + np.eye(3)) / 2.0
        axis = np.sqrt(np.clip(np.diag(B), 0.0, None))
        i = int(np.argmax(axis))
        axis = B[:, i] / math.sqrt(max(B[i, i], 1e-12))
        return axis / np.linalg.norm(axis) * ang
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / (2.0 * math.sin(ang))
    return w * ang


def _adjoint_apply(T: np.ndarray, S: np.ndarray) -> np.ndarray:
    R, p = T[:3, :3], T[:3, 3]
    w = R @ S[:3]
    return np.concatenate([w, np.cross(p, w) + R @ S[3:]])


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


#: one standard DH row as a 4x4 transform (kept under its old name for callers)
_dh = dh_transform


@dataclass(frozen=True)
class ArmKinematics:
    """A serial arm in PoE form, for FK and IK: the description's ``chain`` (joint names,
    6xn space screw axes (omega; v) at the zero pose, approach axis: the tool axis, 0 = x,
    2 = z, that points out of the gripper), ``M`` the tool pose at zero (the chain's, with
    the grasp point offset applied), ``limits`` per joint (the chain's, with the
    acceleration for trajectory timing) and a ``name``. Build with :meth:`from_chain` or
    :meth:`from_description`."""

    chain: ArmChain
    M: np.ndarray
    limits: tuple[JointLimit, ...]
    name: str

    @property
    def joint_names(self) -> tuple[str, ...]:
        return self.chain.joint_names

    @property
    def screws(self) -> np.ndarray:
        return self.chain.screws

    @property
    def approach_axis(self) -> int:
        return self.chain.approach_axis

    @property
    def dof(self) -> int:
        return len(self.chain.joint_names)

    @property
    def lower(self) -> np.ndarray:
        return np.array([lim.lower for lim in self.limits])

    @property
    def upper(self) -> np.ndarray:
        return np.array([lim.upper for lim in self.limits])

    def with_tool_offset(self, T_tool_tcp: np.ndarray, name: str | None = None) -> ArmKinematics:
        """The same arm with its tool frame moved by ``T_tool_tcp`` (4x4)."""
        return ArmKinematics(self.chain, self.M @ T_tool_tcp, self.limits, name or self.name)

    @classmethod
    def from_chain(cls, chain: ArmChain, *, tcp_offset: float | None = None,
                   acceleration: float | None = None) -> ArmKinematics:
        """The arm of ``chain`` with its tool frame moved ``tcp_offset`` [m] along the
        approach axis (None: the chain's own grasp point offset; 0: the tool link
        itself) and every joint's acceleration limit set to ``acceleration`` [rad/s^2]
        (None: the chain's default)."""
        offset = chain.tcp_offset if tcp_offset is None else tcp_offset
        acc = chain.acceleration if acceleration is None else acceleration
        limits = tuple(dataclasses.replace(lim, acceleration=acc) for lim in chain.limits)
        M = chain.M
        if offset != 0.0:
            tcp = np.eye(4)
            tcp[chain.approach_axis, 3] = offset
            M = M @ tcp
        return cls(chain, M, limits, chain.name)

    @classmethod
    def from_description(cls, description: RobotDescription, *, tcp_offset: float | None = None,
                         acceleration: float | None = None) -> ArmKinematics:
        """The arm of a robot description (see :meth:`from_chain`); ValueError when the
        robot has no arm."""
        if description.arm is None:
            raise ValueError(f"robot {description.name} has no arm")
        return cls.from_chain(description.arm, tcp_offset=tcp_offset, acceleration=acceleration)

    # ------------------------------------------------------------------ FK / Jacobian
    def _pre(self) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
        cache = self.__dict__.get("_pre_cache")
        if cache is None:
            cache = []
            for i in range(self.dof):
                w, v = self.screws[:3, i].copy(), self.screws[3:, i].copy()
                W = skew(w)
                W2 = W @ W
                cache.append((w, v, W, W2, W @ v, W2 @ v, np.eye(3)))
            object.__setattr__(self, "_pre_cache", cache)
        return cache

    def fk(self, q: Sequence[float]) -> np.ndarray:
        """``T_armbase_tool`` (4x4) at joint positions ``q`` [rad]."""
        return self.fk_and_jacobian(q, jacobian=False)[0]

    def fk_and_jacobian(self, q: Sequence[float], jacobian: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Tool pose and space Jacobian (6xn, rows omega then v) at ``q``."""
        R = np.eye(3)
        p = np.zeros(3)
        J = np.zeros((6, self.dof))
        for i, (w, v, W, W2, Wv, W2v, eye) in enumerate(self._pre()):
            th = float(q[i])
            if jacobian:
                wi = R @ w
                J[:3, i] = wi
                J[3:, i] = _cross(p, wi) + R @ v
            s, c = math.sin(th), math.cos(th)
            Ri = eye + s * W + (1.0 - c) * W2
            pi = th * v + (1.0 - c) * Wv + (th - s) * W2v
            p = R @ pi + p
            R = R @ Ri
        T = np.eye(4)
        T[:3, :3] = R @ self.M[:3, :3]
        T[:3, 3] = R @ self.M[:3, 3] + p
        return T, J

    @property
    def reach(self) -> float:
        """Largest distance [m] from the first joint's axis point to the tool seen over
        sampled configurations (plus 5 %): a cheap bound for rejecting far IK targets."""
        r = self.__dict__.get("_reach")
        if r is None:
            rng = np.random.default_rng(12345)
            lo, hi = np.maximum(self.lower, -math.pi), np.minimum(self.upper, math.pi)
            base = self._axis_point(0)
            r = max(float(np.linalg.norm(self.fk(rng.uniform(lo, hi))[:3, 3] - base)) for _ in range(400))
            r = r * 1.05 + 0.01
            object.__setattr__(self, "_reach", r)
        return r

    def _axis_point(self, i: int) -> np.ndarray:
        w, v = self.screws[:3, i], self.screws[3:, i]
        return np.cross(w, v)

    def within_limits(self, q: Sequence[float], tol: float = 1e-9) -> bool:
        return all(lim.contains(float(x), tol) for lim, x in zip(self.limits, q))

    # ------------------------------------------------------------------ IK
    def ik(
        self,
        T_target: np.ndarray,
        q_seed: Sequence[float] | None = None,
        *,
        free_approach_rotation: bool = False,
        position_only: bool = False,
        seed: int = 0,
        attempts: int = 20,
        max_iterations: int = 150,
        position_tolerance: float = 5e-4,
        rotation_tolerance: float = 5e-3,
        is_valid: Callable[[np.ndarray], bool] | None = None,
    ) -> np.ndarray | None:
        """Joint positions reaching ``T_target`` (4x4 in the arm base), or None.

        ``free_approach_rotation``: only the approach axis direction must match (any
        rotation about it is accepted; for grasping a box face with a symmetric gripper).
        ``position_only``: ignore orientation. ``attempts``: number of starts (``q_seed``
        first, then seeded random configurations). ``is_valid``: extra acceptance test
        (e.g. collision-free); a rejected solution makes the search go on.
        Tolerances in m and rad.
        """
        T_target = np.asarray(T_target, dtype=float)
        p_t, R_t = T_target[:3, 3], T_target[:3, :3]
        a_t = R_t[:, self.approach_axis]
        lo, hi = self.lower, self.upper
        rng = np.random.default_rng(seed)
        starts: list[np.ndarray] = []
        if q_seed is not None:
            starts.append(np.clip(np.asarray(q_seed, dtype=float), lo, hi))
        while len(starts) < max(1, attempts):
            starts.append(rng.uniform(np.maximum(lo, -math.pi), np.minimum(hi, math.pi)))
        if np.linalg.norm(p_t - self._axis_point(0)) > self.reach:
            return None
        w_rot = 0.25  # m per rad: balances position and orientation errors
        for q0 in starts:
            q = q0.copy()
            best = math.inf
            stall = 0
            for _ in range(max_iterations):
                T, Js = self.fk_and_jacobian(q)
                p, R = T[:3, 3], T[:3, :3]
                e_p = p_t - p
                Jw, Jv = Js[:3], Js[3:]
                Jp = Jv - skew(p) @ Jw
                if position_only:
                    e_r = np.zeros(3)
                    rot_err = 0.0
                    J, e = Jp, e_p
                else:
                    if free_approach_rotation:
                        a = R[:, self.approach_axis]
                        cr = np.cross(a, a_t)
                        s = np.linalg.norm(cr)
                        ang = math.atan2(s, float(np.dot(a, a_t)))
                        if s > 1e-12:
                            e_r = cr / s * ang
                        elif ang > 1.0:  # anti-parallel: any perpendicular axis
                            perp = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
                            e_r = perp / np.linalg.norm(perp) * ang
                        else:
                            e_r = np.zeros(3)
                        P = np.eye(3) - np.outer(a, a)
                        Jr = P @ Jw
                    else:
                        e_r = log_so3(R_t @ R.T)
                        Jr = Jw
                    rot_err = float(np.linalg.norm(e_r))
                    J = np.vstack([Jp, w_rot * Jr])
                    e = np.concatenate([e_p, w_rot * e_r])
                if np.linalg.norm(e_p) < position_tolerance and rot_err < rotation_tolerance:
                    if self.within_limits(q) and (is_valid is None or is_valid(q)):
                        return q
                    break
                err = float(np.linalg.norm(e))
                if err < best * 0.98:
                    best, stall = err, 0
                else:
                    stall += 1
                    if stall > 12:
                        break  # stuck (joint limit or singularity): next start
                lam2 = 1e-4 + 0.01 * min(1.0, err)  # more damping far from the target
                dq = J.T @ np.linalg.solve(J @ J.T + lam2 * np.eye(J.shape[0]), e)
                m = float(np.max(np.abs(dq)))
                if m > 0.4:
                    dq *= 0.4 / m
                q = np.clip(q + dq, lo, hi)
        return None


# --------------------------------------------------------------------------- the arms


def wx250s(*, locobot: bool = True, acceleration: float = 5.0) -> ArmKinematics:
    """The WidowX-250 6DOF (``locobot=True``: LoCoBot mount, heights -0.005825 m); tool
    frame ``ee_gripper_link``. ``acceleration`` [rad/s^2] per joint for trajectory timing
    (not published by Interbotix; a conservative default). Joint ranges, speeds and
    efforts: the arm's joint table (:mod:`mmexec.drivers.descriptions.wx250s`), which the
    driver uses too."""
    return ArmKinematics.from_chain(wx250s_arm.arm_chain(locobot=locobot, acceleration=acceleration))


#: UR5e standard DH rows ``(d, a, alpha)`` [m, m, rad]: the UR arm facts (docs/robots.md 2.1).
UR5E_DH: tuple[tuple[float, float, float], ...] = ur_arm.DH["ur5e"]


def ur5e(*, tcp_offset: float = ur5e_robotiq.TCP_OFFSET, acceleration: float = 3.0) -> ArmKinematics:
    """The UR5e in ROS ``base_link``; tool = ``tool0`` moved ``tcp_offset`` [m] along its z
    (0 gives ``tool0`` itself). Joint limits from the ROS description (elbow +-pi, others
    +-2pi), 180 deg/s; ``acceleration`` [rad/s^2] is not published by UR (a default)."""
    return ArmKinematics.from_chain(ur_arm.arm_chain("ur5e", tcp_offset=tcp_offset, acceleration=acceleration))
