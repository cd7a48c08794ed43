"""Geometry shared by skills, the simulator and the drivers: angle wrap, planar (SE(2))
and spatial (SE(3)) transforms, quaternions and the rigid fit of two point sets.

It sits at capability-contract level (``mmexec.drivers.geometry``, beside
:mod:`mmexec.drivers.interfaces`) so that ``sim/`` and ``drivers/``, which must not import
``skills/``, use the same functions as the skills. Pure ``math`` and ``numpy``; it
imports nothing else of mmexec.

Conventions (as in :mod:`mmexec.drivers.interfaces`): angles in rad, lengths in m,
transforms are 4x4 homogeneous arrays named ``T_<to>_<from>``, SE(2) transforms 3x3;
quaternions are ``(x, y, z, w)`` (pybullet's and ROS's order); roll-pitch-yaw apply as
``R = Rz(yaw) Ry(pitch) Rx(roll)`` (URDF, REP-103).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import overload

import numpy as np

__all__ = [
    "matrix_to_quat",
    "planar_transform",
    "position_quat",
    "quat_to_matrix",
    "rigid_fit",
    "rot_x",
    "rot_y",
    "rot_z",
    "rpy_matrix",
    "se2_matrix",
    "wrap_angle",
    "xyz_rpy_transform",
]

_TWO_PI = 2.0 * math.pi


@overload
def wrap_angle(a: float) -> float: ...


@overload
def wrap_angle(a: np.ndarray) -> np.ndarray: ...


def wrap_angle(a: float | np.ndarray) -> float | np.ndarray:
    """``a`` [rad] wrapped into [-pi, pi): a float for a float, an array (element-wise)
    for an array. ``(a + pi) mod 2 pi - pi``, so an angle already in range can move by
    a few ulp (every caller used this form before it was shared; keep it bit for bit)."""
    return (a + math.pi) % _TWO_PI - math.pi


# --------------------------------------------------------------------------- rotations


def rot_x(a: float) -> np.ndarray:
    """3x3 rotation by ``a`` [rad] about x."""
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(a: float) -> np.ndarray:
    """3x3 rotation by ``a`` [rad] about y."""
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(a: float) -> np.ndarray:
    """3x3 rotation by ``a`` [rad] about z (a heading in the plane)."""
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rpy_matrix(rpy: Sequence[float]) -> np.ndarray:
    """3x3 rotation of roll, pitch, yaw [rad]: ``Rz(yaw) Ry(pitch) Rx(roll)``."""
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array([
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ])


# --------------------------------------------------------------------------- transforms


def se2_matrix(x: float, y: float, theta: float) -> np.ndarray:
    """3x3 homogeneous SE(2) transform of the planar pose (x, y [m], theta [rad])."""
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s, x], [s, c, y], [0.0, 0.0, 1.0]])


def planar_transform(x: float, y: float, theta: float, z: float = 0.0) -> np.ndarray:
    """4x4 transform of a planar pose lifted into 3-D: position (x, y, z) [m], rotation
    ``theta`` [rad] about z (a base pose in ``map``, a box standing on the floor)."""
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s, 0.0, x], [s, c, 0.0, y], [0.0, 0.0, 1.0, z], [0.0, 0.0, 0.0, 1.0]])


def xyz_rpy_transform(xyz: Sequence[float], rpy: Sequence[float]) -> np.ndarray:
    """4x4 transform from a translation ``xyz`` [m] and roll, pitch, yaw [rad]
    (URDF ``<origin xyz rpy>``; R = Rz Ry Rx)."""
    T = np.eye(4)
    T[:3, :3] = rpy_matrix(rpy)
    T[:3, 3] = xyz
    return T


# --------------------------------------------------------------------------- quaternions


def matrix_to_quat(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (x, y, z, w) of a 3x3 rotation matrix (w >= 0)."""
    m = np.asarray(R, dtype=float)
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        q = [(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2]) * 2
        q = [0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s]
    elif m[1, 1] > m[2, 2]:
        s = math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2]) * 2
        q = [(m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s]
    else:
        s = math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1]) * 2
        q = [(m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s, (m[1, 0] - m[0, 1]) / s]
    qa = np.array(q)
    qa /= np.linalg.norm(qa)
    return qa if qa[3] >= 0 else -qa


def position_quat(T: np.ndarray) -> tuple[list[float], list[float]]:
    """A 4x4 transform as position [m] and unit quaternion (x, y, z, w), plain floats (the
    form pybullet takes a pose in)."""
    return [float(v) for v in T[:3, 3]], [float(v) for v in matrix_to_quat(T[:3, :3])]


def quat_to_matrix(q: Sequence[float]) -> np.ndarray:
    """3x3 rotation matrix of quaternion (x, y, z, w) (normalised first)."""
    x, y, z, w = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


# --------------------------------------------------------------------------- fitting


def rigid_fit(src: np.ndarray, dst: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation ``R`` (k x k, det +1, never a reflection) and translation ``t`` minimising
    ``sum |R src_i + t - dst_i|^2`` (Kabsch / Umeyama without scale); ``src`` and ``dst``
    (N, k) with k = 2 or 3 and N >= k, both in the same units (m)."""
    cs, cd = src.mean(axis=0), dst.mean(axis=0)
    u, _, vt = np.linalg.svd((src - cs).T @ (dst - cd))
    D = np.eye(src.shape[1])
    D[-1, -1] = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
    R = vt.T @ D @ u.T
    return R, cd - R @ cs
