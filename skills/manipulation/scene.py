"""Planning scene: the arm, static boxes and perceived items, for collision checking.

Runs on its own pybullet DIRECT client (one per scene, never the simulator's). Every
pose here is in the arm's mount frame (``arm_base``): the robot model is placed so its
``arm_base_link`` is the world origin, and static boxes given in ``map`` are moved into
this frame with the base pose at planning time.

Items follow the seed paper's planning-scene life cycle: **add** when perceived (a box
in the world), **attach** on grasp (it then moves with the tool frame and is checked
against the world and the arm, but not against the gripper links holding it),
**detach** on release (it stays where it is, still ignored by the gripper until removed)
and **remove** once placed.

Validity check (``is_valid(q)``): one ``resetJointStatesMultiDof``, one
``performCollisionDetection`` and one ``getContactPoints``, keeping penetrations
(distance < ``-contact_tolerance``) between pairs that are not allowed. Allowed pairs
are adjacent links (pybullet's EXCLUDE_PARENT) and, like MoveIt's allowed-collision
matrix, link pairs already touching at the zero pose or touching in nearly every sampled
configuration (links rigidly fused in the model).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from types import ModuleType
from typing import Self

import numpy as np

from mmexec.drivers.descriptions import RobotDescription, get
from mmexec.drivers.geometry import matrix_to_quat, quat_to_matrix
from mmexec.drivers.interfaces import SceneBox

__all__ = ["ArmModel", "PlanningScene", "SceneItem", "pb_to_pose", "pose_to_pb"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ArmModel:
    """What the scene needs from a robot model: the URDF file, the planned joints (in
    order), the mount and tool links, gripper joints and the values to hold them at, and
    the links allowed to touch a held item."""

    urdf: str
    arm_joints: tuple[str, ...]
    arm_base_link: str
    tool_link: str
    gripper_joints: tuple[str, ...] = ()
    gripper_positions: tuple[float, ...] = ()
    grasp_links: tuple[str, ...] = ()

    @classmethod
    def from_description(cls, description: RobotDescription, gripper_width: float | None = None) -> ArmModel:
        """The arm of robot ``description`` (its generated URDF used as data, the links
        its description allows to touch a held item), with the gripper held open at
        ``gripper_width`` [m] (default: fully open)."""
        info = description.info
        width = info.gripper_width_range[1] if gripper_width is None else gripper_width
        return cls(
            urdf=str(description.urdf_path),
            arm_joints=tuple(info.arm_joints),
            arm_base_link=info.arm_base_link,
            tool_link=info.tool_link,
            gripper_joints=tuple(info.gripper_joints),
            gripper_positions=tuple(info.width_to_q(width)),
            grasp_links=description.grasp_links,
        )

    @classmethod
    def from_sim_model(cls, name: str, gripper_width: float | None = None) -> ArmModel:
        """:meth:`from_description` of the registered description ``name``
        (:func:`mmexec.drivers.descriptions.get`: KeyError listing the known ones)."""
        return cls.from_description(get(name), gripper_width)


@dataclass
class SceneItem:
    """An item in the scene: box ``size`` [m]; ``T`` its pose in ``arm_base`` (when free)
    or ``T_tool_item`` (when attached)."""

    name: str
    body: int
    size: tuple[float, float, float]
    T: np.ndarray
    attached: bool = False
    released: bool = False


def pose_to_pb(T: np.ndarray) -> tuple[list[float], list[float]]:
    """4x4 -> (position, quaternion xyzw) for pybullet."""
    return [float(x) for x in T[:3, 3]], [float(x) for x in matrix_to_quat(T[:3, :3])]


def pb_to_pose(pos: Sequence[float], quat: Sequence[float]) -> np.ndarray:
    """(position, quaternion xyzw) -> 4x4."""
    T = np.eye(4)
    T[:3, :3] = quat_to_matrix(quat)
    T[:3, 3] = pos
    return T


class PlanningScene:
    """Collision world for one arm (see the module doc). Connects lazily on first use;
    call :meth:`close` (or use it as a context manager) to free the pybullet client.
    pybullet is imported here, when a scene is built, so skill modules load without the
    simulator's engine."""

    def __init__(self, model: ArmModel, *, contact_tolerance: float = 0.0, acm_samples: int = 200, seed: int = 0) -> None:
        import pybullet

        self._pb: ModuleType = pybullet
        self.model = model
        self.contact_tolerance = contact_tolerance
        self._acm_samples = acm_samples
        self._seed = seed
        self._cid: int | None = None
        self._robot = -1
        self._joint_idx: list[int] = []
        self._link_idx: dict[str, int] = {}
        self._link_name: dict[int, str] = {}
        self._tool_idx = -1
        self._root_home: tuple[Sequence[float], Sequence[float]] = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))
        self._allowed: set[tuple[int, int, int, int]] = set()
        self._static: dict[int, str] = {}
        self._items: dict[str, SceneItem] = {}
        self._body_name: dict[int, str] = {}
        self.limits: list[tuple[float, float]] = []
        self.checks = 0

    # ------------------------------------------------------------------ lifecycle
    def __enter__(self) -> Self:
        self._ensure()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Disconnect the pybullet client (idempotent)."""
        if self._cid is not None:
            try:
                self._pb.disconnect(physicsClientId=self._cid)
            finally:
                self._cid = None

    def _ensure(self) -> int:
        if self._cid is not None:
            return self._cid
        cid = self._pb.connect(self._pb.DIRECT)
        self._cid = cid
        # No contactBreakingThreshold here: Bullet keeps it in a process-wide global
        # (gContactBreakingThreshold), so setting it on this client changed contact
        # handling in the simulator's client too (the sim's pads sank into boxes with
        # 1 mm). Near misses beyond the tolerance are filtered in _contacts instead.
        try:
            self._load_robot()
        except Exception:
            self.close()
            raise
        return cid

    def _load_robot(self) -> None:
        cid = self._cid
        m = self.model
        flags = self._pb.URDF_USE_SELF_COLLISION | self._pb.URDF_USE_SELF_COLLISION_EXCLUDE_PARENT
        try:
            robot = self._pb.loadURDF(m.urdf, useFixedBase=True, flags=flags, physicsClientId=cid)
        except self._pb.error as e:
            raise ValueError(f"planning scene: cannot load URDF {m.urdf!r}: {e}") from e
        self._robot = robot
        self._body_name[robot] = "robot"
        joints: dict[str, int] = {}
        for i in range(self._pb.getNumJoints(robot, physicsClientId=cid)):
            info = self._pb.getJointInfo(robot, i, physicsClientId=cid)
            joints[info[1].decode()] = i
            self._link_idx[info[12].decode()] = i
            self._link_name[i] = info[12].decode()
        self._link_name[-1] = self._pb.getBodyInfo(robot, physicsClientId=cid)[0].decode()
        self._link_idx.setdefault(self._link_name[-1], -1)
        missing = [j for j in m.arm_joints + m.gripper_joints if j not in joints]
        if missing:
            raise ValueError(f"planning scene: {m.urdf}: no joint(s) {', '.join(missing)}")
        for ln in (m.arm_base_link, m.tool_link):
            if ln not in self._link_idx:
                raise ValueError(f"planning scene: {m.urdf}: no link {ln!r}")
        self._joint_idx = [joints[j] for j in m.arm_joints]
        self.limits = []
        for j in self._joint_idx:
            info = self._pb.getJointInfo(robot, j, physicsClientId=cid)
            lo, hi = float(info[8]), float(info[9])
            if lo > hi:  # continuous joint
                lo, hi = -2 * math.pi, 2 * math.pi
            self.limits.append((lo, hi))
        self._tool_idx = self._link_idx[m.tool_link]
        for j, v in zip(m.gripper_joints, m.gripper_positions):
            self._pb.resetJointState(robot, joints[j], v, physicsClientId=cid)
        # put arm_base_link at the world origin
        ab = self._link_idx[m.arm_base_link]
        if ab >= 0:
            st = self._pb.getLinkState(robot, ab, computeForwardKinematics=1, physicsClientId=cid)
            T_root_ab = np.linalg.inv(pb_to_pose(*self._pb.getBasePositionAndOrientation(robot, physicsClientId=cid))) @ pb_to_pose(st[4], st[5])
            pos, orn = pose_to_pb(np.linalg.inv(T_root_ab))
            self._pb.resetBasePositionAndOrientation(robot, pos, orn, physicsClientId=cid)
        self._root_home = self._pb.getBasePositionAndOrientation(robot, physicsClientId=cid)
        self._build_acm()

    def _robot_contacts(self) -> set[tuple[int, int]]:
        cid = self._cid
        self._pb.performCollisionDetection(physicsClientId=cid)
        out = set()
        for c in self._pb.getContactPoints(bodyA=self._robot, bodyB=self._robot, physicsClientId=cid):
            if c[8] < -self.contact_tolerance:
                a, b = sorted((c[3], c[4]))
                out.add((a, b))
        return out

    def _build_acm(self) -> None:
        n = len(self._joint_idx)
        self._set_q(np.zeros(n))
        default = self._robot_contacts()
        rng = np.random.default_rng(self._seed)
        counts: dict[tuple[int, int], int] = {}
        lo = np.array([max(a, -math.pi) for a, _ in self.limits])
        hi = np.array([min(b, math.pi) for _, b in self.limits])
        for _ in range(self._acm_samples):
            self._set_q(rng.uniform(lo, hi))
            for pair in self._robot_contacts():
                counts[pair] = counts.get(pair, 0) + 1
        always = {pr for pr, k in counts.items() if k >= 0.95 * self._acm_samples}
        r = self._robot
        for a, b in default | always:
            self._allowed.add((r, a, r, b))
            self._allowed.add((r, b, r, a))
        # links no planned joint moves are rigid w.r.t. each other: never check them, and
        # never check allowed pairs (both skipped in the broadphase, which is the cost)
        moving = self._moving_links()
        fixed = [i for i in self._link_name if i not in moving]
        pairs = {(a, b) for a, b in default | always}
        for i, a in enumerate(fixed):
            for b in fixed[i + 1 :]:
                pairs.add((a, b))
        for a, b in pairs:
            self._pb.setCollisionFilterPair(r, r, a, b, 0, physicsClientId=self._cid)
            self._allowed.add((r, a, r, b))
            self._allowed.add((r, b, r, a))
        log.debug("planning scene: %d allowed self-collision pairs", len(default | always))

    def _moving_links(self) -> set[int]:
        cid = self._cid
        parent = {i: self._pb.getJointInfo(self._robot, i, physicsClientId=cid)[16] for i in self._link_name if i >= 0}
        moving: set[int] = set()
        for i in parent:
            k = i
            while k >= 0:
                if k in self._joint_idx:
                    moving.add(i)
                    break
                k = parent[k]
        return moving

    # ------------------------------------------------------------------ state
    def _set_q(self, q: Sequence[float]) -> None:
        self._pb.resetJointStatesMultiDof(
            self._robot, self._joint_idx, [[float(x)] for x in q], physicsClientId=self._cid
        )

    def tool_pose(self, q: Sequence[float]) -> np.ndarray:
        """``T_armbase_tool`` of the model at ``q`` (pybullet's forward kinematics)."""
        self._ensure()
        self._set_q(q)
        st = self._pb.getLinkState(self._robot, self._tool_idx, computeForwardKinematics=1, physicsClientId=self._cid)
        return pb_to_pose(st[4], st[5])

    # ------------------------------------------------------------------ robot placement
    def place_root(self, x: float, y: float, yaw: float) -> None:
        """Put the robot's root link (the floor frame of a mobile robot's URDF) at the
        planar pose ``(x, y, yaw)`` [m, rad] of the scene's world, for a planner that
        moves the base too (:mod:`mmexec.skills.manipulation.holistic`): the scene's
        world is then ``map``, so static boxes and items must be given in ``map``.
        :meth:`home_root` puts the arm base back at the origin (the default)."""
        cid = self._cid if self._cid is not None else self._ensure()
        h = 0.5 * yaw
        self._pb.resetBasePositionAndOrientation(self._robot, (x, y, 0.0), (0.0, 0.0, math.sin(h), math.cos(h)),
                                                 physicsClientId=cid)

    def home_root(self) -> None:
        """Put the robot back with its arm base link at the world origin (the scene's
        world is the arm base frame again, as every arm planner expects)."""
        cid = self._ensure()
        pos, orn = self._root_home
        self._pb.resetBasePositionAndOrientation(self._robot, pos, orn, physicsClientId=cid)

    # ------------------------------------------------------------------ static world
    def set_static_boxes(self, boxes: Iterable[SceneBox], T_armbase_map: np.ndarray | None = None) -> None:
        """Replace the static boxes. ``SceneBox.pose`` is ``T_map_box``; it is moved into
        the arm base frame with ``T_armbase_map`` (identity: boxes already in arm base)."""
        cid = self._ensure()
        for b in list(self._static):
            self._pb.removeBody(b, physicsClientId=cid)
            self._body_name.pop(b, None)
        self._static.clear()
        T_am = np.eye(4) if T_armbase_map is None else np.asarray(T_armbase_map, dtype=float)
        for box in boxes:
            if min(box.size) <= 0:
                raise ValueError(f"scene box {box.name!r}: sizes must be > 0 m, got {box.size}")
            shape = self._pb.createCollisionShape(self._pb.GEOM_BOX, halfExtents=[s / 2 for s in box.size], physicsClientId=cid)
            pos, orn = pose_to_pb(T_am @ np.asarray(box.pose, dtype=float))
            body = self._pb.createMultiBody(0.0, shape, -1, pos, orn, physicsClientId=cid)
            self._static[body] = box.name
            self._body_name[body] = box.name
        ids = list(self._static)
        for i, a in enumerate(ids):  # static boxes never need checking against each other
            for b in ids[i + 1 :]:
                self._pb.setCollisionFilterPair(a, b, -1, -1, 0, physicsClientId=cid)

    @property
    def static_boxes(self) -> list[str]:
        return list(self._static.values())

    # ------------------------------------------------------------------ items
    @property
    def items(self) -> dict[str, SceneItem]:
        return dict(self._items)

    def add_item(self, name: str, size: tuple[float, float, float], T_armbase_item: np.ndarray) -> None:
        """Add a perceived item (a box of ``size`` [m] centred at ``T_armbase_item``)."""
        cid = self._ensure()
        if name in self._items:
            raise ValueError(f"scene item {name!r} already exists")
        if min(size) <= 0:
            raise ValueError(f"scene item {name!r}: sizes must be > 0 m, got {size}")
        shape = self._pb.createCollisionShape(self._pb.GEOM_BOX, halfExtents=[s / 2 for s in size], physicsClientId=cid)
        pos, orn = pose_to_pb(np.asarray(T_armbase_item, dtype=float))
        body = self._pb.createMultiBody(0.0, shape, -1, pos, orn, physicsClientId=cid)
        for s in self._static:
            self._pb.setCollisionFilterPair(body, s, -1, -1, 0, physicsClientId=cid)
        self._items[name] = SceneItem(name, body, tuple(float(s) for s in size), np.asarray(T_armbase_item, dtype=float).copy())
        self._body_name[body] = name

    def _item(self, name: str) -> SceneItem:
        try:
            return self._items[name]
        except KeyError:
            raise KeyError(f"no scene item {name!r} (items: {', '.join(self._items) or 'none'})") from None

    def attach_item(self, name: str, q: Sequence[float]) -> None:
        """Attach item ``name`` to the tool at arm configuration ``q`` (the grasp): from now
        on it moves with the tool and is checked against the world and the arm, but not
        the gripper links. Static boxes are checked against it again."""
        cid = self._ensure()
        it = self._item(name)
        if it.attached:
            return
        T_tool = self.tool_pose(q)
        it.T = np.linalg.inv(T_tool) @ it.T
        it.attached = True
        self._set_grasp_filter(it, enable=False)
        for s in self._static:
            self._pb.setCollisionFilterPair(it.body, s, -1, -1, 1, physicsClientId=cid)

    def clear_attached_from_static(self, name: str, q: Sequence[float], max_shift: float = 0.02) -> float:
        """Move attached item ``name``'s model out of the static boxes it penetrates at
        ``q`` (the grasp): it was modelled from the marker estimate, and a few mm of
        estimate error put a box lifted off a board into that board, failing the retract's
        start. Each round pushes it along the deepest contact's normal by the penetration
        depth (plus 0.5 mm), at most ``max_shift`` [m] in all (like MoveIt's fix-start-
        state adapter, but only for the held item). Returns the shift applied [m];
        ValueError when more than ``max_shift`` would be needed (a real collision)."""
        cid = self._ensure()
        it = self._item(name)
        if not it.attached:
            raise ValueError(f"scene item {name!r} is not attached")
        T_tool = self.tool_pose(q)
        total = np.zeros(3)
        for _ in range(6):
            pos, orn = pose_to_pb(T_tool @ it.T)
            self._pb.resetBasePositionAndOrientation(it.body, pos, orn, physicsClientId=cid)
            self._pb.performCollisionDetection(physicsClientId=cid)
            deepest = None
            for s in self._static:
                for c in self._pb.getContactPoints(bodyA=it.body, bodyB=s, physicsClientId=cid):
                    if c[8] < -self.contact_tolerance and (deepest is None or c[8] < deepest[8]):
                        deepest = c
            if deepest is None:
                return float(np.linalg.norm(total))
            step = np.asarray(deepest[7], dtype=float) * (-deepest[8] + 5e-4)  # normal on B points towards A
            if np.linalg.norm(total + step) > max_shift:
                raise ValueError(f"held {name} is {-deepest[8] * 1e3:.1f} mm into {self._name(deepest[2], -1)}, "
                                 f"more than {max_shift * 1e3:.0f} mm of estimate error")
            total += step
            T_world = T_tool @ it.T
            T_world[:3, 3] += step
            it.T = np.linalg.inv(T_tool) @ T_world
        raise ValueError(f"held {name} still touches the static scene after {np.linalg.norm(total) * 1e3:.1f} mm")

    def detach_item(self, name: str, q: Sequence[float]) -> None:
        """Release item ``name`` where the tool leaves it at ``q``. It stays in the world,
        still ignored by the gripper links (which touch it) until removed."""
        cid = self._ensure()
        it = self._item(name)
        if not it.attached:
            return
        it.T = self.tool_pose(q) @ it.T
        it.attached = False
        it.released = True
        pos, orn = pose_to_pb(it.T)
        self._pb.resetBasePositionAndOrientation(it.body, pos, orn, physicsClientId=cid)
        for s in self._static:
            self._pb.setCollisionFilterPair(it.body, s, -1, -1, 0, physicsClientId=cid)

    def remove_item(self, name: str) -> None:
        """Remove item ``name`` from the scene."""
        cid = self._ensure()
        it = self._items.pop(name, None)
        if it is None:
            raise KeyError(f"no scene item {name!r}")
        self._pb.removeBody(it.body, physicsClientId=cid)
        self._body_name.pop(it.body, None)

    def _set_grasp_filter(self, it: SceneItem, enable: bool) -> None:
        for ln in self.model.grasp_links:
            li = self._link_idx.get(ln)
            if li is not None:
                self._pb.setCollisionFilterPair(it.body, self._robot, -1, li, int(enable), physicsClientId=self._cid)

    # ------------------------------------------------------------------ checks
    def _contacts(self, q: Sequence[float]) -> list[tuple[int, int, int, int, float]]:
        cid = self._cid
        self._set_q(q)
        attached = [it for it in self._items.values() if it.attached]
        if attached:
            st = self._pb.getLinkState(self._robot, self._tool_idx, computeForwardKinematics=1, physicsClientId=cid)
            T_tool = pb_to_pose(st[4], st[5])
            for it in attached:
                pos, orn = pose_to_pb(T_tool @ it.T)
                self._pb.resetBasePositionAndOrientation(it.body, pos, orn, physicsClientId=cid)
        self._pb.performCollisionDetection(physicsClientId=cid)
        out = []
        tol = -self.contact_tolerance
        allowed = self._allowed
        for c in self._pb.getContactPoints(physicsClientId=cid):
            if c[8] < tol and (c[1], c[3], c[2], c[4]) not in allowed:
                out.append((c[1], c[3], c[2], c[4], c[8]))
        return out

    def is_valid(self, q: Sequence[float]) -> bool:
        """True when configuration ``q`` [rad] is inside the joint limits and collision-free
        (arm vs itself, static boxes, items; a held item vs everything but the gripper)."""
        if self._cid is None:
            self._ensure()
        self.checks += 1
        for x, (lo, hi) in zip(q, self.limits):
            if x < lo - 1e-9 or x > hi + 1e-9:
                return False
        return not self._contacts(q)

    def collisions(self, q: Sequence[float]) -> list[tuple[str, str]]:
        """Colliding pairs at ``q`` as readable names (``"robot/upper_arm_link"``,
        ``"shelf_board"``), for failure reasons."""
        self._ensure()
        out = []
        for ba, la, bb, lb, _ in self._contacts(q):
            out.append((self._name(ba, la), self._name(bb, lb)))
        return sorted(set(out))

    def _name(self, body: int, link: int) -> str:
        if body == self._robot:
            return f"robot/{self._link_name.get(link, link)}"
        return self._body_name.get(body, f"body{body}")
