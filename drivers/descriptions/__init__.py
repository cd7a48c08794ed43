"""Robot descriptions: one home for what mmexec knows about each robot model.

Kinematics (joint tables and limits, DH / PoE chains), tool and grasp links, base
footprint, sensor frames, collision geometry and the URDF link tree of each robot live
here, at capability-contract level: data and numpy math, importing only
:mod:`mmexec.drivers.interfaces` and :mod:`mmexec.config`. A backend hands the active
robot's :class:`RobotDescription` to skills as ``Robot.description``; the simulator
builds its model from it; the device drivers read their kinematic facts from the arm
modules (:mod:`.wx250s`, :mod:`.ur`).

Modules: :mod:`.description` (:class:`RobotDescription`), :mod:`.chain` (:class:`ArmChain`,
DH to PoE), :mod:`.model_info` (:class:`ModelInfo`), :mod:`.linktree` (links, joints,
primitive geometry); arm and gripper families :mod:`.wx250s`, :mod:`.ur`,
:mod:`.robotiq_2f85`, the UR platform :mod:`.ur_platform`; one module per robot:
:mod:`.locobot_wx250s`, :mod:`.ur5e_robotiq`, :mod:`.ur3e_robotiq`.

Adding a robot: write its module (a ``DESCRIPTION``), list it in :data:`DESCRIPTIONS`
below, and give it a config (``sim.robot``, ``robot.description``); then run
``python -m mmexec.sim.models.urdfgen`` to write its URDF.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

from mmexec.config.yamlload import did_you_mean
from mmexec.drivers.descriptions import locobot_wx250s, ur3e_robotiq, ur5e_robotiq
from mmexec.drivers.descriptions.chain import ArmChain, dh_to_poe, dh_transform
from mmexec.drivers.descriptions.description import URDF_DIR, RobotDescription
from mmexec.drivers.descriptions.linktree import Geom, Joint, Link, LinkTree
from mmexec.drivers.descriptions.model_info import ModelInfo

__all__ = [
    "DESCRIPTIONS",
    "URDF_DIR",
    "ArmChain",
    "Geom",
    "Joint",
    "Link",
    "LinkTree",
    "ModelInfo",
    "RobotDescription",
    "dh_to_poe",
    "dh_transform",
    "get",
    "names",
]

#: Every robot mmexec knows, by name (the registry: explicit, in this order).
DESCRIPTIONS: Mapping[str, RobotDescription] = MappingProxyType(
    {d.name: d for d in (locobot_wx250s.DESCRIPTION, ur5e_robotiq.DESCRIPTION, ur3e_robotiq.DESCRIPTION)}
)


def names() -> tuple[str, ...]:
    """The known description names, in registry order."""
    return tuple(DESCRIPTIONS)


def get(name: str) -> RobotDescription:
    """The description called ``name``; KeyError listing the known ones (with a
    did-you-mean hint) when there is none."""
    try:
        return DESCRIPTIONS[name]
    except KeyError:
        hint = did_you_mean(name, DESCRIPTIONS)
        raise KeyError(f"unknown robot model {name!r}{hint} (known: {', '.join(DESCRIPTIONS)})") from None
