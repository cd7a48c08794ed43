"""A pan/tilt head's kinematics from a robot description: where the camera is for given
head joints, and which joints look at a point.

:meth:`HeadModel.of` walks the description's link tree from the root link
(``base_footprint``, the interfaces' ``base_link``) to the camera's optical link; the two
movable joints on that path must be the model's ``pan_tilt_joints`` (pan first), every
other joint fixed. None for a robot without a head (the UR platforms' camera rides on the
wrist). Frames and units as in :mod:`mmexec.drivers.interfaces`: metres, radians, 4x4
transforms ``T_<to>_<from>``; the optical frame has z forward, x right, y down.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from mmexec.drivers.descriptions.description import RobotDescription
from mmexec.drivers.descriptions.linktree import Joint
from mmexec.drivers.geometry import xyz_rpy_transform
from mmexec.drivers.interfaces import JointLimit

__all__ = ["HeadModel"]


def _axis_rotation(axis: Sequence[float], q: float) -> np.ndarray:
    """4x4 rotation by ``q`` [rad] about the unit ``axis`` (Rodrigues)."""
    k = np.asarray(axis, dtype=float)
    k = k / np.linalg.norm(k)
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    T = np.eye(4)
    T[:3, :3] = np.eye(3) + math.sin(q) * K + (1.0 - math.cos(q)) * (K @ K)
    return T


def _origin(j: Joint) -> np.ndarray:
    return xyz_rpy_transform(j.xyz, j.rpy)


@dataclass(frozen=True)
class HeadModel:
    """The chain root -> pan joint -> tilt joint -> optical frame of one robot model.

    ``T_root_pan``: the pan joint's frame (before its rotation) in the root link;
    ``T_pan_tilt``: the tilt joint's frame in the pan joint's child link; ``T_tilt_optical``:
    the optical frame in the tilt joint's child link (the link carrying the camera);
    ``pan_axis`` / ``tilt_axis``: the joints' axes in their child frames; ``limits``: pan
    and tilt limits from the link tree (position [rad], velocity [rad/s], effort [N m]).
    """

    joint_names: tuple[str, str]
    T_root_pan: np.ndarray
    T_pan_tilt: np.ndarray
    T_tilt_optical: np.ndarray
    pan_axis: tuple[float, float, float]
    tilt_axis: tuple[float, float, float]
    limits: tuple[JointLimit, JointLimit]
    camera_link: str

    @classmethod
    def of(cls, description: RobotDescription) -> HeadModel | None:
        """The head of ``description``, or None when its model has no pan/tilt joints.
        ValueError when the link tree's path to the camera does not match them."""
        info = description.info
        if not info.pan_tilt_joints:
            return None
        if len(info.pan_tilt_joints) != 2:
            raise ValueError(f"{description.name}: pan_tilt_joints must name two joints, got {info.pan_tilt_joints}")
        tree = description.urdf_tree()
        by_child = {j.child: j for j in tree.joints}
        path: list[Joint] = []
        link = info.camera_optical_link
        while link != info.root_link:
            j = by_child.get(link)
            if j is None:
                raise ValueError(f"{description.name}: no joint path from {info.root_link} to {info.camera_optical_link}")
            path.append(j)
            link = j.parent
        path.reverse()
        movable = [j for j in path if j.kind != "fixed"]
        if tuple(j.name for j in movable) != tuple(info.pan_tilt_joints):
            raise ValueError(f"{description.name}: the movable joints to the camera are "
                             f"{[j.name for j in movable]}, expected {list(info.pan_tilt_joints)}")
        pan, tilt = movable
        parts: list[np.ndarray] = [np.eye(4), np.eye(4), np.eye(4)]
        segment = 0
        camera_link = tilt.child
        for j in path:
            parts[segment] = parts[segment] @ _origin(j)
            if j is pan or j is tilt:
                segment += 1
        lims = tuple(JointLimit(j.name, j.lower, j.upper, j.velocity, effort=j.effort) for j in (pan, tilt))
        return cls((pan.name, tilt.name), parts[0], parts[1], parts[2], pan.axis, tilt.axis,
                   lims, camera_link)  # type: ignore[arg-type]

    def T_root_camera_link(self, pan: float, tilt: float) -> np.ndarray:
        """``T_base_link`` of the link carrying the camera (the tilt joint's child) at
        ``pan``, ``tilt`` [rad]."""
        return (self.T_root_pan @ _axis_rotation(self.pan_axis, pan) @ self.T_pan_tilt
                @ _axis_rotation(self.tilt_axis, tilt))

    def T_root_optical(self, pan: float, tilt: float) -> np.ndarray:
        """``T_base_camera``: the optical frame in ``base_link`` at ``pan``, ``tilt`` [rad]."""
        return self.T_root_camera_link(pan, tilt) @ self.T_tilt_optical

    def motion(self, pan: float, tilt: float) -> np.ndarray:
        """``T(pan, tilt) @ inv(T(0, 0))`` of the camera link: applied on the left of a
        camera pose calibrated at pan = tilt = 0 (a real robot's hand-measured mount), it
        gives the pose at ``pan``, ``tilt``."""
        return self.T_root_camera_link(pan, tilt) @ np.linalg.inv(self.T_root_camera_link(0.0, 0.0))

    def aim(self, point: Sequence[float], *, iterations: int = 8) -> tuple[float, float]:
        """Pan and tilt [rad] that put ``point`` (x, y, z [m] in ``base_link``) on the
        optical axis (the image centre), within 1e-6 rad for points beyond the camera's
        offsets from the axes; not clipped to :attr:`limits` (the head's :meth:`point`
        refuses what is outside them). Fixed-point iteration on the point's bearing in the
        optical frame, which converges because the camera sits a few centimetres off the
        axes it turns about."""
        target = np.array([float(point[0]), float(point[1]), float(point[2]), 1.0])
        pan = math.atan2(target[1] - self.T_root_pan[1, 3], target[0] - self.T_root_pan[0, 3])
        tilt = 0.0
        for _ in range(iterations):
            p = np.linalg.inv(self.T_root_optical(pan, tilt)) @ target
            if p[2] <= 1e-6:
                tilt = 0.0
                continue
            d_pan = -math.atan2(p[0], p[2])   # optical x right: turn left (pan +) to bring it in
            d_tilt = math.atan2(p[1], p[2])   # optical y down: tilt down (tilt +)
            pan, tilt = pan + d_pan, tilt + d_tilt
            if abs(d_pan) < 1e-7 and abs(d_tilt) < 1e-7:
                break
        return pan, tilt
