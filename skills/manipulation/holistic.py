"""Holistic base + arm planning: where must the base stand so the arm reaches a tool pose?

The paper (locobot-holistic-planning-dangerous-objects, III-B, IV-C) adds three virtual
joints at the root of the robot's URDF, a prismatic x, a prismatic y and a revolute yaw,
and lets MoveIt's RRT* plan the whole robot to the pre-grasp; the base's final pose goes
to ``move_base`` and the arm's part is executed once the base is there. This module does
the same over our own planning scene:

**Model** (:class:`HolisticModel`): the state is 9-D for a 6-joint arm,
``(base_x, base_y, base_yaw, q_1 ... q_6)``: the base's floor frame (``base_link`` of
the interfaces, the URDF's root) in ``map`` [m, m, rad], then the arm joints [rad] in
the description's order. Bounds: x and y within a box of ``HolisticConfig.box`` [m]
either side of the robot's start, widened to hold every base pose within the arm's reach
of the target (clipped to the map's extent), yaw within pi of the
start heading, the arm joints within their limits. The tool pose of a state is
``T_map_base(x, y, yaw) @ T_base_armbase (the description's arm mount) @ FK(q)``.

**Validity** (:meth:`HolisticModel.is_valid`): the base's footprint free in the
occupancy map inflated by the base radius and the navigation margin (a cell lookup,
first: it rejects most invalid states for the price of a few microseconds), then the arm's
planning scene (:class:`~mmexec.skills.manipulation.scene.PlanningScene`: the robot's
own links, the static boxes in ``map``, known items) with the whole robot model placed at
the base pose (:meth:`PlanningScene.place_root`): the base body and the arm against the
shelves, the arm against itself.

**Goal**: a set of goal states from inverse kinematics sampled over base poses (the
paper's MoveIt samples IK for its goal too). Base poses are drawn around the target
(arm base within the arm's horizontal reach at the target's height, facing the target
within ``yaw_spread``), and filtered as arrays: inside the bounds, footprint free, in the
start's free region of the map (so navigation can get there). The survivors nearest the
robot first, each gets the arm's collision-free IK for the pre-grasp (seeded by the
reach posture turned towards the target), and, when a grasp pose is given, the grasp
must have IK within ``max_grasp_jump`` of it too (the straight approach is then short).
``goal_count`` such states form an OMPL ``GoalStates``.

**Search**: OMPL RRT-Connect (default) or RRT* (to its first solution) over the 9-D
space from the start state, ``time_limit`` per attempt, ``attempts`` attempts (each with
fresh goal samples). The result (:class:`HolisticResult`) is the goal state the tree
connected to: the final base pose (for navigation) and the arm configuration, and the
9-D path. Like the paper, the two parts are executed separately: the base drives to
the pose (A* + tracking, which the free-region filter keeps possible), then the arm is
re-planned from the pose the base actually reached (:func:`replan_arm`).

Nothing here blocks a tick by itself: a call is bounded by its budget and runs on the
arm workspace's worker thread in the skill (:mod:`mmexec.skills.manipulation.holistic_skill`);
:attr:`HolisticPlanner.stop` makes a running call return "cancelled" early.

Frames: ``map`` (z up), base ``base_link`` on the floor, ``arm_base`` the arm mount.
Units: m, rad, s.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from mmexec.drivers.descriptions import RobotDescription
from mmexec.drivers.geometry import wrap_angle
from mmexec.drivers.interfaces import Pose2D, SceneBox
from mmexec.skills.manipulation.batch_ik import batch_ik
from mmexec.skills.manipulation.kinematics import ArmKinematics
from mmexec.skills.manipulation.planner import (
    CANCELLED,
    ArmPlanner,
    PlannerConfig,
    PlanResult,
    ompl_setup,
    ompl_solve,
    ompl_state,
    time_parametrize,
)
from mmexec.skills.manipulation.scene import ArmModel, PlanningScene
from mmexec.skills.navigation.grid import CostMap

__all__ = [
    "BASE_JOINTS",
    "HolisticConfig",
    "HolisticModel",
    "HolisticPlanner",
    "HolisticResult",
    "armbase_in_map",
    "back_off_distance",
    "replan_arm",
]

log = logging.getLogger(__name__)

#: Names of the three virtual joints (the paper's prismatic x, prismatic y, revolute z).
BASE_JOINTS = ("base_x", "base_y", "base_yaw")

#: [rad] largest joint move of :func:`replan_arm`'s escape from a start posture in
#: collision to the drive posture (a few mrad of tracking error on a stow posture that
#: nearly touches the robot itself, e.g. the LoCoBot's fingers by its arm base).
ESCAPE_LIMIT = 0.06

#: goals kept per plan() that failed only the navigation tolerance or the drive margin
SPARE_GOALS = 12

#: scene item name of the carried object while a goal's carry posture is checked
CARRY_ITEM = "holistic_carried"
#: [m] per side the carried object's box is grown by in that check: a held object sags
#: a few mm in the fingers and its estimate is off by as much (a box carried 1 mm above
#: a 0.2 m blocker in the model rested on it in the sim)
CARRY_MARGIN = 0.02

#: [m] waypoint spacing and [rad] largest joint step of the straight pre-grasp -> grasp
#: line a goal must allow (the arm planner's ``cartesian_path`` defaults, which the pick uses)
APPROACH_STEP = 0.01
APPROACH_JOINT_STEP = 0.25

#: Candidate base poses solved per IK batch (nearest first); goal sampling stops at the
#: first chunk after which ``goal_count`` goals are found.
GOAL_CHUNK = 64


@dataclass(frozen=True)
class HolisticConfig:
    """Settings of :class:`HolisticPlanner`.

    ``algorithm`` "rrtconnect" or "rrtstar" (stopped at its first solution);
    ``time_limit`` [s] of OMPL's search per attempt and ``attempts`` (each with fresh goal
    samples); ``box`` [m]: the base's x and y bounds either side of the start
    (widened to hold the target's surroundings); ``range``
    [m|rad] OMPL's step (0: its default, a fifth of the space's extent: metres and
    radians here, so most steps near the target collide); ``resolution`` [m|rad]: longest step between two
    checked states of an edge (Euclidean over the 9 coordinates, so no coordinate moves
    more); ``goal_count`` goal states per attempt, drawn from ``goal_candidates`` base
    poses; ``yaw_spread`` [rad]: the arm base faces the target within this; ``min_reach``
    [m]: nearest the arm base comes to the target horizontally; ``max_grasp_jump`` [rad]:
    largest joint change from the pre-grasp to the grasp's IK (when a grasp is given);
    ``tolerance`` [m, rad]: a goal's base pose shifted this much (x, y and yaw, four
    ways) must still reach the pre-grasp, as navigation stops near, not at, the pose
    ((0, 0): not checked); ``drive_margin`` [m, rad]: the arm's drive posture must be
    free with the base anywhere within this of a goal's base pose (checked on the ring
    of 8 directions at that distance, each at the heading and turned by +-the angle,
    and turned on the spot): the base drives there with the arm stowed and stops off
    the pose by up to navigation's goal and heading tolerances plus the localiser's
    error, and an arm whose start posture is in collision cannot move at all ((0, 0):
    the exact pose only); ``seed`` for the goal sampler and OMPL (deterministic for a given query sequence)."""

    algorithm: str = "rrtconnect"
    time_limit: float = 1.0
    attempts: int = 5
    box: float = 2.5
    range: float = 0.5
    resolution: float = 0.03
    goal_count: int = 6
    goal_candidates: int = 300
    yaw_spread: float = math.radians(60.0)
    min_reach: float = 0.12
    max_grasp_jump: float = 1.0
    tolerance: tuple[float, float] = (0.03, 0.03)
    drive_margin: tuple[float, float] = (0.06, 0.06)
    seed: int | None = 0

    def validate(self) -> list[str]:
        errs = []
        if self.algorithm not in ("rrtconnect", "rrtstar"):
            errs.append(f"algorithm: expected 'rrtconnect' or 'rrtstar', got {self.algorithm!r}")
        for name in ("time_limit", "box", "resolution", "max_grasp_jump"):
            if not getattr(self, name) > 0:
                errs.append(f"{name}: must be > 0, got {getattr(self, name)}")
        for name in ("attempts", "goal_count", "goal_candidates"):
            if getattr(self, name) < 1:
                errs.append(f"{name}: must be >= 1, got {getattr(self, name)}")
        if not 0 <= self.yaw_spread <= math.pi:
            errs.append(f"yaw_spread: must be in [0, pi] rad, got {self.yaw_spread}")
        if not self.min_reach >= 0 or not self.range >= 0 or not min(self.tolerance) >= 0 \
                or not min(self.drive_margin) >= 0:
            errs.append("min_reach, range, tolerance and drive_margin must be >= 0")
        return errs


@dataclass(frozen=True)
class HolisticResult:
    """Outcome of :meth:`HolisticPlanner.plan`: ``success``; ``reason`` when not;
    ``planning_time`` [s] (goal sampling and search); ``base_pose`` the final base pose in
    ``map`` (the navigation goal); ``arm`` the arm configuration there [rad]; ``path`` the
    9-D states from the start; ``attempts`` used; ``goals`` goal states of the last
    attempt; ``checks`` validity checks; ``start_adjusted`` when the arm's start posture
    touched the robot itself and the search started just off it; ``tolerant`` False when
    the goal was found only without the navigation tolerance (the last attempt waives
    it when no earlier one found a goal)."""

    success: bool
    reason: str = ""
    planning_time: float = 0.0
    base_pose: Pose2D | None = None
    arm: tuple[float, ...] | None = None
    path: list[tuple[float, ...]] = field(default_factory=list)
    attempts: int = 0
    goals: int = 0
    checks: int = 0
    start_adjusted: bool = False
    tolerant: bool = True


def armbase_in_map(base: Pose2D, mount: Sequence[float]) -> np.ndarray:
    """``T_map_armbase`` (4x4) for the base at ``base`` (``map``) and the arm ``mount``
    (``T_base_armbase``, a translation [m])."""
    c, s = math.cos(base.theta), math.sin(base.theta)
    T = np.eye(4)
    T[:2, :2] = ((c, -s), (s, c))
    T[:3, 3] = (base.x + c * mount[0] - s * mount[1], base.y + s * mount[0] + c * mount[1], mount[2])
    return T


#: [m] how far a base that stopped inside the inflated map may back off before the line
#: behind it must be free (two cells of the lab maps, as :meth:`HolisticPlanner.plan`'s start)
BACK_OFF_EXEMPT = 0.10


def back_off_distance(cm: CostMap, pose: Pose2D, distance: float) -> float:
    """How far [m] a base at ``pose`` (``map``) can back straight off, up to ``distance``:
    from a free pose as far as the line behind stays free in the inflated map ``cm``; from
    a pose inside the inflation (a holistic stand-off beside the blocker) the line may stay
    blocked for :data:`BACK_OFF_EXEMPT` (0 when it is still blocked there: backing
    further into an obstacle), then only as far as it stays free."""
    step, d, free, was_free = 0.5 * cm.resolution, 0.0, 0.0, cm.is_free(pose.x, pose.y)
    c, s = math.cos(pose.theta), math.sin(pose.theta)
    while d < distance:
        d = min(distance, d + step)
        if cm.is_free(pose.x - d * c, pose.y - d * s):
            was_free, free = True, d
        elif was_free or d > BACK_OFF_EXEMPT:
            break
    return free


def _cells(cm: CostMap, xs: np.ndarray, ys: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rows, columns and in-grid flags of map points (arrays) [m], as
    :func:`~mmexec.skills.navigation.grid.world_to_cell` for each."""
    o = cm.grid.origin
    c, s = math.cos(o.theta), math.sin(o.theta)
    dx, dy = np.asarray(xs, dtype=float) - o.x, np.asarray(ys, dtype=float) - o.y
    gx, gy = c * dx + s * dy, -s * dx + c * dy
    rows = np.floor(gy / cm.resolution + 1e-9).astype(np.int64)
    cols = np.floor(gx / cm.resolution + 1e-9).astype(np.int64)
    inside = (rows >= 0) & (rows < cm.grid.height) & (cols >= 0) & (cols < cm.grid.width)
    return rows, cols, inside


class HolisticModel:
    """The 9-D base + arm model of one robot over one map and planning scene (see the
    module doc). ``scene`` is used from one thread at a time (the arm workspace's worker
    in the skill); the model places the robot in it and puts it back in :meth:`release`.
    ``boxes`` (static, in ``map``) and ``items`` (name -> (size [m], T_map_item)) are
    written into the scene by :meth:`prepare`. ``mount``: ``T_base_armbase`` translation
    [m] (default: the description's arm mount; a skill passes the arm's own)."""

    def __init__(self, description: RobotDescription, kin: ArmKinematics, scene: PlanningScene, costmap: CostMap,
                 mount: Sequence[float] | None = None) -> None:
        if description.arm is None:
            raise ValueError(f"robot model {description.name!r} has no arm to plan for")
        if tuple(scene.model.arm_joints) != tuple(kin.joint_names):
            raise ValueError(f"holistic model: scene joints {scene.model.arm_joints} differ from {kin.joint_names}")
        self.description = description
        self.kin = kin
        self.scene = scene
        self.mount = np.asarray(description.arm_mount if mount is None else mount, dtype=float)
        self.joint_names: tuple[str, ...] = BASE_JOINTS + tuple(kin.joint_names)
        self._items: list[str] = []
        #: ``(x, y, r)`` [m]: base positions within ``r`` of ``(x, y)`` skip the footprint
        #: test (a start that stopped a little inside the inflation; the scene still
        #: checks the base body), None: none
        self.exempt: tuple[float, float, float] | None = None
        self.use_map(costmap)
        # the first joint's axis point (the shoulder), in arm base: the reach is from there
        w, v = kin.screws[:3, 0], kin.screws[3:, 0]
        self._shoulder = np.cross(w, v)
        self.checks = 0

    @classmethod
    def build(cls, description: RobotDescription, costmap: CostMap, *, tcp_offset: float | None = None,
              kin: ArmKinematics | None = None) -> HolisticModel:
        """A model with its own planning scene (close it with :meth:`close`)."""
        kin = kin or ArmKinematics.from_description(description, tcp_offset=tcp_offset)
        return cls(description, kin, PlanningScene(ArmModel.from_description(description)), costmap)

    def close(self) -> None:
        self.scene.close()

    def use_map(self, costmap: CostMap) -> None:
        """Plan over ``costmap`` (the occupancy map inflated by the base radius and margin)
        from now on; its free regions are labelled once here."""
        self.costmap = costmap
        free = (~costmap.blocked).astype(np.uint8)
        self._labels = cv2.connectedComponents(free, connectivity=4)[1]

    @property
    def dof(self) -> int:
        return len(self.joint_names)

    # ------------------------------------------------------------------ scene
    def prepare(self, boxes: Sequence[SceneBox], items: dict[str, tuple[tuple[float, float, float], np.ndarray]] | None = None) -> None:
        """Write the static ``boxes`` (``map``) and extra ``items`` (perceived objects, an
        obstacle seen in front of the target: name -> (size, ``T_map_item``)) into the
        scene, whose world is ``map`` while this model plans. Free items the scene held
        (in an older arm base frame) are removed first; held ones stay attached."""
        sc = self.scene
        sc.set_static_boxes(boxes)
        for name, it in list(sc.items.items()):
            if not it.attached:
                sc.remove_item(name)
        self._items = []
        for name, (size, T) in (items or {}).items():
            sc.add_item(name, size, T)
            self._items.append(name)

    def release(self) -> None:
        """Remove the items :meth:`prepare` added and put the robot back at the arm base
        origin (the arm planners' frame)."""
        for name in self._items:
            if name in self.scene.items:
                self.scene.remove_item(name)
        self._items = []
        self.scene.home_root()

    # ------------------------------------------------------------------ geometry
    def T_map_armbase(self, x: float, y: float, yaw: float) -> np.ndarray:
        """The arm mount in ``map`` for base pose ``(x, y, yaw)``."""
        return armbase_in_map(Pose2D(float(x), float(y), float(yaw)), self.mount)

    def tool_pose(self, state: Sequence[float]) -> np.ndarray:
        """``T_map_tool`` of a 9-D state (the arm's PoE forward kinematics)."""
        return self.T_map_armbase(state[0], state[1], state[2]) @ self.kin.fk(state[3:])

    def footprint_free(self, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
        """For arrays of base positions [m] in ``map``: True where the footprint is free in
        the inflated map (off the map counts as blocked)."""
        rows, cols, inside = _cells(self.costmap, xs, ys)
        out = np.zeros(rows.shape, dtype=bool)
        out[inside] = ~self.costmap.blocked[rows[inside], cols[inside]]
        return out

    def region(self, x: float, y: float) -> int:
        """Label of the free region of the inflated map holding ``(x, y)`` (4-connected
        cells, so A* connects any two of its cells); 0 when blocked or off the map. A
        blocked start (the base a little inside the inflation) takes the region of the
        nearest free cell within 0.3 m."""
        rows, cols, inside = _cells(self.costmap, np.array([x]), np.array([y]))
        lab = int(self._labels[rows[0], cols[0]]) if inside[0] else 0
        if lab == 0:
            near = self.costmap.nearest_free(x, y, 0.3)
            if near is not None:
                rows, cols, inside = _cells(self.costmap, np.array([near[0]]), np.array([near[1]]))
                lab = int(self._labels[rows[0], cols[0]]) if inside[0] else 0
        return lab

    def regions(self, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
        """Free-region labels of arrays of map points (0: blocked or off the map)."""
        rows, cols, inside = _cells(self.costmap, xs, ys)
        out = np.zeros(rows.shape, dtype=np.int64)
        out[inside] = self._labels[rows[inside], cols[inside]]
        return out

    def arm_valid(self, x: float, y: float, yaw: float, q: Sequence[float]) -> bool:
        """The arm's planning scene with the robot at base pose ``(x, y, yaw)``."""
        self.scene.place_root(x, y, yaw)
        return self.scene.is_valid(q)

    def is_valid(self, state: Sequence[float]) -> bool:
        """Footprint free in the inflated map (except within :attr:`exempt`), then the
        robot model (base and arm) free in the planning scene at ``state`` (9-D)."""
        self.checks += 1
        x, y = state[0], state[1]
        rows, cols, inside = _cells(self.costmap, np.array([x]), np.array([y]))
        if not inside[0] or self.costmap.blocked[rows[0], cols[0]]:
            ex = self.exempt
            if ex is None or (x - ex[0]) ** 2 + (y - ex[1]) ** 2 > ex[2] ** 2:
                return False
        return self.arm_valid(x, y, state[2], state[3:])

    def collisions(self, state: Sequence[float]) -> list[tuple[str, str]]:
        """What collides at ``state`` (readable pairs; the footprint as ``("base footprint", "map")``)."""
        out = []
        if not self.footprint_free(np.array([state[0]]), np.array([state[1]]))[0]:
            out.append(("base footprint", "map"))
        self.scene.place_root(state[0], state[1], state[2])
        return out + self.scene.collisions(state[3:])

    def horizontal_reach(self, dz: float) -> float:
        """Largest horizontal distance [m] from the arm's first axis to a tool point
        ``dz`` [m] above the arm base (from the arm's sampled reach)."""
        h = dz - float(self._shoulder[2])
        r = self.kin.reach
        return math.sqrt(max(0.0, r * r - h * h)) + float(math.hypot(self._shoulder[0], self._shoulder[1]))


class HolisticPlanner:
    """OMPL over the 9-D model (see the module doc). :attr:`stop` (a threading.Event set
    from any thread) makes a running :meth:`plan` return "cancelled"."""

    def __init__(self, model: HolisticModel, config: HolisticConfig | None = None) -> None:
        self.model = model
        self.config = config or HolisticConfig()
        errs = self.config.validate()
        if errs:
            raise ValueError("HolisticConfig: " + "; ".join(errs))
        self.stop = threading.Event()
        #: (carry posture, object size, back-off [m]) while a plan() checks the carried object
        self._carry: tuple[np.ndarray, tuple[float, ...], float] | None = None
        #: goals of a plan() valid at their pose but not within the navigation tolerance
        #: or the drive margin: the last, goal-less attempt uses them too
        self._spare: list[tuple[float, ...]] = []

    # ------------------------------------------------------------------ goals
    def _candidates(self, start: Pose2D, target: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                    rng: np.random.Generator, cfg: HolisticConfig) -> tuple[np.ndarray, dict[str, int]]:
        """Base poses (n x 3) around ``target`` (3,) whose arm base is within reach,
        inside the bounds, with the footprint free and in the start's region, nearest the
        start first; and the counts at each filter (for a failure's reason)."""
        m = self.model
        n = cfg.goal_candidates
        r_max = m.horizontal_reach(float(target[2]) - float(m.mount[2]))
        r_min = min(cfg.min_reach, 0.5 * r_max)
        # area-uniform radius in the annulus, any direction from the target
        r = np.sqrt(rng.uniform(r_min * r_min, r_max * r_max, n))
        phi = rng.uniform(-math.pi, math.pi, n)
        ax, ay = target[0] + r * np.cos(phi), target[1] + r * np.sin(phi)
        yaw = phi + math.pi + rng.uniform(-cfg.yaw_spread, cfg.yaw_spread, n)  # the arm base faces the target
        c, s = np.cos(yaw), np.sin(yaw)
        bx = ax - (c * m.mount[0] - s * m.mount[1])
        by = ay - (s * m.mount[0] + c * m.mount[1])
        yaw = start.theta + np.mod(yaw - start.theta + math.pi, 2 * math.pi) - math.pi  # into the yaw bounds
        counts = {"drawn": n}
        ok = (bx >= lo[0]) & (bx <= hi[0]) & (by >= lo[1]) & (by <= hi[1])
        counts["in the bounds"] = int(ok.sum())
        ok &= m.footprint_free(bx, by)
        counts["free for the footprint"] = int(ok.sum())
        ok &= m.regions(bx, by) == m.region(start.x, start.y)
        counts["reachable by the base"] = int(ok.sum())
        poses = np.stack([bx[ok], by[ok], yaw[ok]], axis=1)
        d = np.hypot(poses[:, 0] - start.x, poses[:, 1] - start.y)
        return poses[np.argsort(d, kind="stable")], counts

    def _goal_states(self, poses: np.ndarray, T_map_pre: np.ndarray, T_map_grasp: np.ndarray | None,
                     seeds: Sequence[Sequence[float]], stow: np.ndarray, free_rotation: bool, cfg: HolisticConfig,
                     rng: np.random.Generator) -> tuple[list[tuple[float, ...]], int]:
        """Up to ``goal_count`` valid 9-D goal states from the base ``poses`` (n x 3) in
        order, and how many poses (of those tried) had an IK solution at all. The
        pre-grasp's IK runs for :data:`GOAL_CHUNK` poses at once
        (:func:`~mmexec.skills.manipulation.batch_ik.batch_ik`), from each seed posture
        turned towards the target, then from one random start; the collision checks and the
        grasp's IK only for solved poses, in order, until enough.
        A goal also needs the arm's ``stow`` posture free at its base pose (the base drives
        there with the arm stowed) and the pre-grasp's IK from the base pose shifted by
        ``tolerance``."""
        m = self.model
        kin = m.kin
        k = len(poses)
        if k == 0:
            return [], 0
        # the pre-grasp in each candidate's arm base frame
        c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
        R_ab = np.zeros((k, 3, 3))
        R_ab[:, 0, 0], R_ab[:, 0, 1], R_ab[:, 1, 0], R_ab[:, 1, 1], R_ab[:, 2, 2] = c, -s, s, c, 1.0
        t_ab = np.stack([poses[:, 0] + c * m.mount[0] - s * m.mount[1],
                         poses[:, 1] + s * m.mount[0] + c * m.mount[1], np.full(k, m.mount[2])], axis=1)
        Rt = np.transpose(R_ab, (0, 2, 1))
        T_pre = np.zeros((k, 4, 4))
        T_pre[:, 3, 3] = 1.0
        T_pre[:, :3, :3] = Rt @ T_map_pre[:3, :3]
        T_pre[:, :3, 3] = np.einsum("bij,bj->bi", Rt, T_map_pre[:3, 3] - t_ab)
        bearing = np.arctan2(T_pre[:, 1, 3], T_pre[:, 0, 3])
        q = np.zeros((k, kin.dof))
        solved = np.zeros(k, dtype=bool)
        lo, hi = kin.lower, kin.upper
        starts = []
        for seed in seeds:
            s0 = np.asarray(seed, dtype=float)
            p = kin.fk(s0)[:3, 3]
            Q0 = np.tile(s0, (k, 1))
            Q0[:, 0] = np.clip(s0[0] + np.mod(bearing - math.atan2(float(p[1]), float(p[0])) + math.pi, 2 * math.pi)
                               - math.pi, lo[0], hi[0])
            starts.append(Q0)
        starts.append(rng.uniform(np.maximum(lo, -math.pi), np.minimum(hi, math.pi), (k, kin.dof)))
        goals: list[tuple[float, ...]] = []
        # in chunks, nearest first: an easy query stops after the first chunk or two
        for c0 in range(0, k, GOAL_CHUNK):
            chunk = np.arange(c0, min(k, c0 + GOAL_CHUNK))
            for Q0 in starts:
                todo = chunk[~solved[chunk]]
                if todo.size == 0 or self.stop.is_set() or len(goals) >= cfg.goal_count:
                    break
                qs, ok = batch_ik(kin, T_pre[todo], Q0[todo], free_approach_rotation=free_rotation, max_iterations=80)
                q[todo[ok]] = qs[ok]
                solved[todo[ok]] = True
                goals += self._accept(todo[ok], poses, q, Rt, t_ab, T_map_pre, T_map_grasp, stow, free_rotation, cfg,
                                      cfg.goal_count - len(goals))
            if self.stop.is_set() or len(goals) >= cfg.goal_count:
                break
        return goals, int(solved.sum())

    def _accept(self, rows: np.ndarray, poses: np.ndarray, q: np.ndarray, Rt: np.ndarray, t_ab: np.ndarray,
                T_map_pre: np.ndarray, T_map_grasp: np.ndarray | None, stow: np.ndarray, free_rotation: bool,
                cfg: HolisticConfig, wanted: int) -> list[tuple[float, ...]]:
        """The goal states among the solved candidate ``rows``, in order, at most ``wanted``."""
        m = self.model
        goals: list[tuple[float, ...]] = []
        for i in rows:
            if self.stop.is_set() or len(goals) >= wanted:
                break
            bx, by, byaw = (float(v) for v in poses[i])
            if not m.arm_valid(bx, by, byaw, q[i]) or not m.scene.is_valid(stow):
                continue
            if T_map_grasp is not None:
                T_am = np.eye(4)
                T_am[:3, :3], T_am[:3, 3] = Rt[i], -Rt[i] @ t_ab[i]
                qg = self._approach(T_am @ T_map_pre, T_am @ T_map_grasp, q[i], free_rotation)
                if qg is None or float(np.max(np.abs(qg - q[i]))) > cfg.max_grasp_jump:
                    continue
                if self._carry is not None and not self._carry_clear(bx, by, byaw, qg, T_map_grasp, cfg):
                    continue
            goal = (bx, by, byaw, *(float(v) for v in q[i]))
            if not self._tolerant(bx, by, byaw, q[i], stow, T_map_pre, free_rotation, cfg) \
                    or not self.drive_clear(bx, by, byaw, stow, cfg.drive_margin):
                if len(self._spare) < SPARE_GOALS:
                    self._spare.append(goal)  # valid at the pose itself: the last attempt's fallback
                continue
            goals.append(goal)
        return goals

    def _approach(self, T_pre: np.ndarray, T_grasp: np.ndarray, q_pre: np.ndarray,
                  free_rotation: bool) -> np.ndarray | None:
        """The straight tool line from the pre-grasp to the grasp (both 4x4 in the arm
        base frame) as the pick will move it (the arm planner's ``cartesian_path``): IK
        every :data:`APPROACH_STEP` seeded by the previous waypoint from ``q_pre``, no
        joint moving more than :data:`APPROACH_JOINT_STEP` between two, each waypoint
        collision-free in the scene as placed. The grasp's joints, or None."""
        m = self.model
        p0, p1 = T_pre[:3, 3], T_grasp[:3, 3]
        n = max(1, math.ceil(float(np.linalg.norm(p1 - p0)) / APPROACH_STEP))
        q = q_pre
        for k in range(1, n + 1):
            T = T_grasp.copy()
            T[:3, 3] = p0 + (p1 - p0) * k / n
            qn = m.kin.ik(T, q, free_approach_rotation=free_rotation, attempts=1, max_iterations=60)
            if qn is None or float(np.max(np.abs(qn - q))) > APPROACH_JOINT_STEP or not m.scene.is_valid(qn):
                return None
            q = qn
        return q

    def _carry_clear(self, x: float, y: float, yaw: float, q_grasp: np.ndarray, T_map_grasp: np.ndarray,
                     cfg: HolisticConfig) -> bool:
        """The object (a box of the carry size at the grasp frame, grown by
        :data:`CARRY_MARGIN` per side), held at ``q_grasp``, and the arm in the carry
        posture are free with the base within ``drive_margin`` of the goal ``(x, y, yaw)``
        backed off as the pick will (:func:`back_off_distance`; :meth:`drive_clear` with
        the object attached)."""
        assert self._carry is not None
        q_carry, size, back = self._carry
        sc = self.model.scene
        sc.place_root(x, y, yaw)
        sc.add_item(CARRY_ITEM, tuple(v + 2.0 * CARRY_MARGIN for v in size), T_map_grasp)
        d = back_off_distance(self.model.costmap, Pose2D(x, y, yaw), back) if back > 0 else 0.0
        try:
            sc.attach_item(CARRY_ITEM, q_grasp)
            return self.drive_clear(x - d * math.cos(yaw), y - d * math.sin(yaw), yaw, q_carry, cfg.drive_margin)
        finally:
            sc.remove_item(CARRY_ITEM)

    def _tolerant(self, x: float, y: float, yaw: float, q: np.ndarray, stow: np.ndarray, T_map_pre: np.ndarray,
                  free_rotation: bool, cfg: HolisticConfig) -> bool:
        """With the base pose shifted by ``cfg.tolerance`` four ways ((+d, 0, +a), (-d, 0,
        -a), (0, +d, -a), (0, -d, +a) in the base's own axes), the stowed arm is free and
        the pre-grasp has a collision-free IK (seeded by ``q``)."""
        d, a = cfg.tolerance
        if d == 0 and a == 0:
            return True
        m = self.model
        c, s = math.cos(yaw), math.sin(yaw)
        for fx, fy, fa in ((d, 0.0, a), (-d, 0.0, -a), (0.0, d, -a), (0.0, -d, a)):
            px, py, pyaw = x + c * fx - s * fy, y + s * fx + c * fy, yaw + fa
            T = np.linalg.inv(m.T_map_armbase(px, py, pyaw)) @ T_map_pre
            if not m.arm_valid(px, py, pyaw, stow):
                return False
            qs = m.kin.ik(T, q, free_approach_rotation=free_rotation, attempts=1, max_iterations=60)
            if qs is None or not m.scene.is_valid(qs):
                return False
        return True

    def drive_clear(self, x: float, y: float, yaw: float, q_drive: Sequence[float],
                    margin: tuple[float, float]) -> bool:
        """The arm's drive posture ``q_drive`` [rad] is collision-free with the base at
        ``(x, y, yaw)`` (``map``) and anywhere within ``margin`` ([m, rad]) of it: on the
        ring of 8 directions at that distance, each at the heading and turned by +-the
        angle, and turned on the spot (:attr:`HolisticConfig.drive_margin`)."""
        m = self.model
        d, a = margin
        shifts = [(0.0, 0.0)]
        if d > 0:
            shifts += [(d * math.cos(k * math.pi / 4), d * math.sin(k * math.pi / 4)) for k in range(8)]
        turns = (0.0, -a, a) if a > 0 else (0.0,)
        return all(m.arm_valid(x + dx, y + dy, yaw + da, q_drive) for dx, dy in shifts for da in turns)

    # ------------------------------------------------------------------ plan
    def bounds(self, start: Pose2D, target: Sequence[float] | None = None,
               cfg: HolisticConfig | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bounds of the 9-D state for a base starting at ``start``: x and
        y within ``box`` of it, widened to hold every base pose within the arm's reach of
        ``target`` (map point [m]) too, clipped to the map; yaw within pi of the start
        heading; the arm's joint limits (a continuous joint: +-2 pi)."""
        cfg = cfg or self.config
        m = self.model
        g = m.costmap.grid
        corners = np.array([[0, 0], [g.width, 0], [0, g.height], [g.width, g.height]], dtype=float) * g.resolution
        c, s = math.cos(g.origin.theta), math.sin(g.origin.theta)
        mx = g.origin.x + c * corners[:, 0] - s * corners[:, 1]
        my = g.origin.y + s * corners[:, 0] + c * corners[:, 1]
        xs, ys = [start.x - cfg.box, start.x + cfg.box], [start.y - cfg.box, start.y + cfg.box]
        if target is not None:
            r = m.kin.reach + float(np.hypot(m.mount[0], m.mount[1])) + 0.05
            xs += [target[0] - r, target[0] + r]
            ys += [target[1] - r, target[1] + r]
        lo = [max(min(xs), float(mx.min())), max(min(ys), float(my.min())), start.theta - math.pi]
        hi = [min(max(xs), float(mx.max())), min(max(ys), float(my.max())), start.theta + math.pi]
        for a, b in m.scene.limits:
            lo.append(a)
            hi.append(b)
        return np.array(lo), np.array(hi)

    def plan(self, start: Pose2D, q_start: Sequence[float], T_map_pre: np.ndarray, *,
             T_map_grasp: np.ndarray | None = None, seeds: Sequence[Sequence[float]] = (),
             q_drive: Sequence[float] | None = None, free_approach_rotation: bool = False,
             config: HolisticConfig | None = None, q_carry: Sequence[float] | None = None,
             carry_size: Sequence[float] | None = None, back_off: float = 0.0) -> HolisticResult:
        """Plan the robot from base pose ``start`` (``map``) and arm joints ``q_start``
        [rad] until the tool is at ``T_map_pre`` (4x4 in ``map``, the pre-grasp). With
        ``T_map_grasp`` a goal also needs the grasp's IK near it. ``seeds``: arm postures
        that start the goal IK (turned towards the target), e.g. the profile's reach
        pose. ``q_drive``: the arm posture the base drives in (default ``q_start``), which
        must be free at the goal's base pose too. ``q_carry`` and ``carry_size``: the
        posture the arm carries the object in after the pick and the object's box [m] in
        the axes of the grasp frame (``T_map_grasp``): held at the grasp, it must be free
        in that posture within ``drive_margin`` of where the base stands when the arm
        goes there: the goal backed off by ``back_off`` [m] as far as the map allows
        (:func:`back_off_distance`; the pick backs off first), since the object hangs below
        the gripper and over a low blocker it can rest on it. A start a little inside the inflated
        map's obstacles (within 2 cells) may leave them. The scene must have been
        :meth:`HolisticModel.prepare`-d; it is left with the robot placed anywhere (call
        :meth:`HolisticModel.release`)."""
        cfg = config or self.config
        m = self.model
        t0 = time.perf_counter()
        checks0 = m.scene.checks
        target = np.asarray(T_map_pre, dtype=float)[:3, 3]
        lo, hi = self.bounds(start, target, cfg)
        q0 = np.clip(np.asarray(q_start, dtype=float), lo[3:], hi[3:])
        state0 = np.concatenate([[start.x, start.y, start.theta], q0])
        drive = q0 if q_drive is None else np.clip(np.asarray(q_drive, dtype=float), lo[3:], hi[3:])
        rng = np.random.default_rng(cfg.seed)

        def fail(reason: str, used: int = 0, goals: int = 0) -> HolisticResult:
            return HolisticResult(False, reason, time.perf_counter() - t0, attempts=used, goals=goals,
                                  checks=m.scene.checks - checks0)

        if not m.footprint_free(np.array([start.x]), np.array([start.y]))[0] and m.region(start.x, start.y) == 0:
            return fail(f"start ({start.x:.2f}, {start.y:.2f}) is blocked in the inflated map")
        seeds = list(seeds) + [q0]
        # a base that stopped a little inside the inflation (but clear of everything, as
        # the scene checks) may leave it: the footprint test spares its surroundings
        m.exempt = None if m.footprint_free(np.array([start.x]), np.array([start.y]))[0] else \
            (start.x, start.y, 2.0 * m.costmap.resolution)
        if q_carry is not None and carry_size is not None and T_map_grasp is not None:
            self._carry = (np.clip(np.asarray(q_carry, dtype=float), lo[3:], hi[3:]),
                           tuple(float(v) for v in carry_size), float(back_off))
        self._spare = []
        try:
            return self._plan(start, state0, q0, drive, target, lo, hi, T_map_pre, T_map_grasp, seeds,
                              free_approach_rotation, cfg, rng, t0, checks0)
        finally:
            m.exempt = None
            self._carry = None
            self._spare = []

    def _plan(self, start: Pose2D, state0: np.ndarray, q0: np.ndarray, drive: np.ndarray, target: np.ndarray,
              lo: np.ndarray, hi: np.ndarray, T_map_pre: np.ndarray, T_map_grasp: np.ndarray | None,
              seeds: list[Sequence[float]], free_approach_rotation: bool, cfg: HolisticConfig,
              rng: np.random.Generator, t0: float, checks0: int) -> HolisticResult:
        """:meth:`plan`'s attempts (its checks done)."""
        m = self.model

        def fail(reason: str, used: int = 0, goals: int = 0) -> HolisticResult:
            return HolisticResult(False, reason, time.perf_counter() - t0, attempts=used, goals=goals,
                                  checks=m.scene.checks - checks0)

        used, goals = 0, []
        adjusted = tolerant = False
        loose: set[tuple[float, ...]] = set()  # goals found without the navigation tolerance
        for attempt in range(cfg.attempts):
            if self.stop.is_set():
                return fail(CANCELLED, used, len(goals))
            used = attempt + 1
            # attempts after goal-less ones draw twice the candidates (up to 8 x), and the
            # last of several goal-less attempts waives the navigation tolerance
            acfg = cfg if goals else replace(cfg, goal_candidates=cfg.goal_candidates * min(8, 2 ** attempt))
            tolerant = bool(goals) or attempt < cfg.attempts - 1 or attempt == 0
            if not tolerant:
                acfg = replace(acfg, tolerance=(0.0, 0.0), drive_margin=(0.0, 0.0))
            poses, counts = self._candidates(start, target, lo, hi, rng, acfg)
            new, with_ik = self._goal_states(poses, T_map_pre, T_map_grasp, seeds, drive, free_approach_rotation,
                                             acfg, rng)
            if not tolerant:
                new = new + [g for g in self._spare if g not in new][:max(0, cfg.goal_count - len(new))]
                loose.update(new)
            # goals accumulate over the attempts (a search that failed to reach them in its
            # time may reach them, or the new ones, in the next)
            goals = (goals + new)[-3 * cfg.goal_count:]
            if self.stop.is_set():
                return fail(CANCELLED, used, len(goals))
            if not goals:
                if attempt + 1 < cfg.attempts:
                    continue
                chain = ", ".join(f"{v} {k}" for k, v in counts.items())
                what = ("a collision-free IK" + (", the grasp near it" if T_map_grasp is not None else "")
                        + ", room for the stowed arm"
                        + (f" within {cfg.drive_margin[0]:g} m, {cfg.drive_margin[1]:g} rad of the pose and the "
                           "navigation tolerance" if tolerant else ""))
                return fail(f"no base pose within reach of the pre-grasp at ({target[0]:.2f}, {target[1]:.2f}, "
                            f"{target[2]:.2f}): of {chain}, {with_ik} had an IK and none {what}", used)
            start_state = state0
            if not m.is_valid(start_state):
                start_state, adjusted = self._fix_start(state0, np.asarray(goals[0]), lo, hi)
                if start_state is None:
                    pairs = ", ".join(f"{a} vs {b}" for a, b in m.collisions(state0)[:3])
                    return fail(f"start in collision: {pairs}", used, len(goals))
            path = self._ompl(start_state, goals, lo, hi, cfg, attempt)
            if path is not None:
                if adjusted:
                    path.insert(0, tuple(float(v) for v in state0))
                end = path[-1]
                reached = min(goals, key=lambda g: sum((a - b) ** 2 for a, b in zip(g, end)))
                return HolisticResult(True, "", time.perf_counter() - t0, Pose2D(end[0], end[1], wrap_angle(end[2])),
                                      tuple(end[3:]), path, used, len(goals), m.scene.checks - checks0, adjusted,
                                      reached not in loose)
        if self.stop.is_set():
            return fail(CANCELLED, used, len(goals))
        return fail(f"no plan within {cfg.time_limit:g} s x {cfg.attempts} attempts "
                    f"({len(goals)} goal states in the last)", used, len(goals))

    def _fix_start(self, state0: np.ndarray, goal: np.ndarray, lo: np.ndarray,
                   hi: np.ndarray) -> tuple[np.ndarray | None, bool]:
        """A start whose arm posture touches only the robot itself (the LoCoBot's sleep
        pose rests on its camera tower in the model) is moved along the straight line of
        the arm joints towards the goal's until valid (at most half way): the arm leaves
        such a rest pose along that line anyway. Other collisions: (None, False)."""
        m = self.model
        pairs = m.collisions(state0)
        if not pairs or not all(a.startswith("robot/") and b.startswith("robot/") for a, b in pairs):
            return None, False
        d = goal[3:] - state0[3:]
        n = max(1, math.ceil(float(np.max(np.abs(d))) / 0.02))
        for k in range(1, n // 2 + 1):
            s = state0.copy()
            s[3:] = np.clip(state0[3:] + d * k / n, lo[3:], hi[3:])
            if m.is_valid(s):
                return s, True
        return None, False

    def _ompl(self, start: np.ndarray, goals: list[tuple[float, ...]], lo: np.ndarray, hi: np.ndarray,
              cfg: HolisticConfig, attempt: int) -> list[tuple[float, ...]] | None:
        from ompl import base as ob

        n = self.model.dof
        ss, si = ompl_setup(list(zip(lo, hi)), self.model.is_valid, resolution=cfg.resolution, seed=cfg.seed,
                            algorithm=cfg.algorithm, step=cfg.range)
        ss.setStartState(ompl_state(si, start))
        goal = ob.GoalStates(si)
        for g in goals:
            goal.addState(ompl_state(si, g))
        ss.setGoal(goal)
        if not ompl_solve(ss, cfg.time_limit, self.stop):
            log.info("holistic: attempt %d found no plan", attempt + 1)
            return None
        return [tuple(float(s[i]) for i in range(n)) for s in ss.getSolutionPath().getStates()]


def replan_arm(planner: ArmPlanner, reached: Pose2D, mount: Sequence[float], q_now: Sequence[float],
               T_map_pre: np.ndarray, boxes: Sequence[SceneBox], *, seeds: Sequence[Sequence[float]] = (),
               free_approach_rotation: bool = False, config: PlannerConfig | None = None,
               q_escape: Sequence[float] | None = None, escape_limit: float = ESCAPE_LIMIT) -> PlanResult:
    """The arm's part, re-planned from the base pose actually ``reached`` (``map``): the
    static ``boxes`` (``map``) moved into the arm base frame through ``reached`` and the
    arm ``mount`` (``T_base_armbase`` translation [m]), then RRT-Connect (or the
    planner's algorithm) from ``q_now`` to the pre-grasp ``T_map_pre``, IK seeded first by
    ``seeds`` (the holistic plan's arm configuration: the same solution family when the
    base stopped close to where it was planned). The scene's robot must be at home
    (:meth:`HolisticModel.release`).

    A start in collision (the measured posture a few mrad off a drive posture that nearly
    touches something) is left by a short escape only when it is safe: ``q_escape`` (the
    drive posture the arm was sent to) collision-free here and within ``escape_limit``
    [rad] of ``q_now`` in every joint; the path then starts with that straight move from
    ``q_now`` (the planner plans from ``q_escape``). Otherwise "start in collision: ..."
    as the planner says."""
    T_am = np.linalg.inv(armbase_in_map(reached, mount))
    planner.scene.set_static_boxes(boxes, T_am)
    q0 = np.asarray(q_now, dtype=float)
    start = q0
    if q_escape is not None and not planner.scene.is_valid(q0):
        qe = np.asarray(q_escape, dtype=float)
        if qe.shape == q0.shape and float(np.max(np.abs(qe - q0))) <= escape_limit and planner.scene.is_valid(qe):
            log.info("holistic: arm start in collision (%s); escaping %.3f rad to the drive posture",
                     ", ".join(f"{a} vs {b}" for a, b in planner.scene.collisions(q0)[:2]), float(np.max(np.abs(qe - q0))))
            start = qe
    res = planner.plan_to_pose(start, T_am @ np.asarray(T_map_pre, dtype=float), ik_seeds=seeds,
                               free_approach_rotation=free_approach_rotation, config=config)
    if start is q0 or not res.success:
        return res
    cfg = config or planner.config
    path = [tuple(float(v) for v in q0), *res.path]
    traj = time_parametrize(planner.kin.joint_names, path, planner.kin.limits, velocity_scale=cfg.velocity_scale,
                            acceleration_scale=cfg.acceleration_scale, sample_period=cfg.sample_period)
    return replace(res, path=path, trajectory=traj)
