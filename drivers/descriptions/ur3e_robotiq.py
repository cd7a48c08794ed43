"""UR3e with a Robotiq 2F-85 and a wrist RGB-D camera on the UR5e's differential-drive box
base (docs/robots.md section 2; the platform: :mod:`.ur_platform`).

The arm is the official UR3e DH table (docs/robots.md 2.1, :mod:`.ur`), with its limits
(2.2: wrist 3 turns without limit). The arm mount is a sim assumption, also listed in
docs/sim.md. Lengths m, angles rad.
"""

from __future__ import annotations

from mmexec.drivers.descriptions import ur_platform

__all__ = ["DESCRIPTION", "INFO", "MOUNT"]

MOUNT = (0.12, 0.0, 0.33)       # arm base_link in base_footprint

DESCRIPTION = ur_platform.description("ur3e_robotiq", "ur3e", MOUNT,
                                      sleep_pose=(0.0, -1.9, 2.3, -1.97, -1.5708, 0.0))
INFO = DESCRIPTION.info
