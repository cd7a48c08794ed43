"""UR5e with a Robotiq 2F-85 and a wrist RGB-D camera on a differential-drive box base
(docs/robots.md section 2; the platform: :mod:`.ur_platform`).

The arm mount is a sim assumption, also listed in docs/sim.md. Lengths m, angles rad.
"""

from __future__ import annotations

from mmexec.drivers.descriptions import ur_platform
from mmexec.drivers.descriptions.linktree import LinkTree

__all__ = ["DESCRIPTION", "INFO", "MOUNT", "TCP_OFFSET", "urdf_tree"]

MOUNT = (0.12, 0.0, 0.33)       # arm base_link in base_footprint: on the base's top, 0.12 ahead of its centre
TCP_OFFSET = ur_platform.TCP_OFFSET

DESCRIPTION = ur_platform.description("ur5e_robotiq", "ur5e", MOUNT,
                                      sleep_pose=(0.0, -1.9, 2.3, -1.97, -1.5708, 0.0))
INFO = DESCRIPTION.info


def urdf_tree() -> LinkTree:
    """The UR5e platform's link tree (:func:`ur_platform.urdf_tree
    <mmexec.drivers.descriptions.ur_platform.urdf_tree>`)."""
    return DESCRIPTION.urdf_tree()
