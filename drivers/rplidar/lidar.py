"""The :class:`~mmexec.drivers.interfaces.Lidar` capability on an RPLIDAR A2.

A thin adapter: the reader thread of :class:`~mmexec.drivers.rplidar.device.RplidarDevice`
does the work, so :meth:`RplidarLidar.scan` returns at once with the newest complete scan.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from mmexec.drivers.interfaces import LaserScan, Lidar
from mmexec.drivers.rplidar.device import RplidarDevice, RplidarError

__all__ = ["RplidarLidar"]


class RplidarLidar(Lidar):
    """360 degree scans from an RPLIDAR, with the lidar's mount on the robot.

    ``T_base_lidar``: pose of the lidar frame (CCW scan angles, angle 0 along its +x;
    on the LoCoBot ``laser_frame_link``, yawed by pi) in ``base_link``, 4x4.
    """

    def __init__(self, device: RplidarDevice, T_base_lidar: np.ndarray | None = None) -> None:
        T = np.eye(4) if T_base_lidar is None else np.array(T_base_lidar, dtype=float)
        if T.shape != (4, 4):
            raise ValueError(f"T_base_lidar must be 4x4, got shape {T.shape}")
        T.flags.writeable = False
        self.device = device
        self.T_base_lidar = T

    def scan(self) -> LaserScan | None:
        """The newest complete revolution (ranges [m], ``inf`` no return, ``nan`` not
        measured; clock stamp of its first node), or None before the first one and while
        the device reports a fault (see :attr:`fault`). Never blocks."""
        s = self.device.latest_scan()
        return None if s is None else dataclasses.replace(s, T_base_lidar=self.T_base_lidar)

    @property
    def fault(self) -> RplidarError | None:
        """Why :meth:`scan` returns None (watchdog, link lost), or None when scanning."""
        return self.device.fault

    def close(self) -> None:
        """STOP, motor off, release the port."""
        self.device.close()
