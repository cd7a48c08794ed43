"""What mmexec knows about one robot model, at capability-contract level (data and numpy
math, no device code): :class:`RobotDescription`.

A backend hands the active robot's description to skills as ``Robot.description``
(:mod:`mmexec.drivers.interfaces`); the simulator builds its model from it, the device
drivers read their kinematic facts from the description modules, and the planners take
their kinematics and collision model from it. Nothing else decides by a model's name.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from mmexec.drivers.descriptions.chain import ArmChain
from mmexec.drivers.descriptions.linktree import LinkTree, Vec3
from mmexec.drivers.descriptions.model_info import ModelInfo

__all__ = ["URDF_DIR", "RobotDescription"]

#: Where the generated URDF files are kept: package data of :mod:`mmexec.sim.models`
#: (``python -m mmexec.sim.models.urdfgen`` writes them from the descriptions'
#: :attr:`RobotDescription.urdf_tree`). The planning scene loads them as data, so the
#: folder is named here rather than through an import of the simulator.
URDF_DIR = Path(__file__).resolve().parents[2] / "sim" / "models"


@dataclass(frozen=True, eq=False)
class RobotDescription:
    """One robot model (compare descriptions by ``name``).

    * ``info``: frame, joint and link names and the model's constants (gripper, base,
      camera; :class:`ModelInfo`);
    * ``arm``: the arm's kinematic chain in ``arm_base`` (:class:`ArmChain`: PoE screws,
      tool pose, joint limits, approach axis, grasp point offset), None without an arm;
    * ``arm_mount`` [m]: ``arm_base`` (``info.arm_base_link``) in ``base_link``
      (``info.root_link``, on the floor), a pure translation;
    * ``gripper_links``: the links besides the fingers and the tool link that hold or
      touch a grasped item (a planner does not count their contacts with it);
    * ``urdf_tree``: builds the model's link tree (links, joints, collision geometry),
      which :mod:`mmexec.sim.models.urdfgen` writes to :attr:`urdf_path`.
    """

    name: str
    info: ModelInfo
    arm: ArmChain | None
    arm_mount: Vec3
    gripper_links: tuple[str, ...]
    urdf_tree: Callable[[], LinkTree]

    def __post_init__(self) -> None:
        if self.info.name != self.name:
            raise ValueError(f"robot description {self.name}: its model info is named {self.info.name!r}")
        if self.arm is not None and self.arm.joint_names != self.info.arm_joints:
            raise ValueError(f"robot description {self.name}: arm chain joints {list(self.arm.joint_names)} "
                             f"differ from the model's arm joints {list(self.info.arm_joints)}")

    @property
    def urdf_path(self) -> Path:
        """Absolute path of the generated URDF of this model (in :data:`URDF_DIR`)."""
        return URDF_DIR / self.info.urdf

    @property
    def grasp_links(self) -> tuple[str, ...]:
        """Links allowed to touch a held item: the fingers, the tool link and
        :attr:`gripper_links`, in that order."""
        info = self.info
        return tuple(info.finger_links) + ((info.tool_link,) if info.tool_link else ()) + self.gripper_links
