"""Joint-space motion planning with OMPL, time parametrisation, Cartesian straight lines.

:class:`ArmPlanner` plans between joint configurations of the arm of a
:class:`~mmexec.skills.manipulation.scene.PlanningScene` (validity = the scene's
collision check) with OMPL 2.0.1 (RRTConnect by default, RRT* to its first solution),
simplifies the path, and times it into a :class:`JointTrajectory` that respects each
joint's velocity and acceleration limits: every segment between waypoints is a
synchronised trapezoidal (or triangular) velocity profile starting and ending at rest,
sampled densely so the Arm's linear interpolation follows it.

Every call is synchronous and bounded by ``time_limit`` x ``attempts``; skills run it on
a worker thread (a tick never waits for it). :attr:`ArmPlanner.stop` is a threading.Event
another thread sets to make a running call return early with reason "cancelled": OMPL's
termination condition polls it, and IK starts, attempts and Cartesian waypoints check it.
Nothing here sleeps.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from itertools import pairwise
from typing import Any

import numpy as np

from mmexec.drivers.geometry import matrix_to_quat, quat_to_matrix
from mmexec.drivers.interfaces import JointLimit, JointTrajectory
from mmexec.skills.manipulation.kinematics import ArmKinematics
from mmexec.skills.manipulation.scene import PlanningScene

__all__ = ["CANCELLED", "ArmPlanner", "PlanResult", "PlannerConfig", "ompl_setup", "ompl_solve", "ompl_state",
           "time_parametrize"]

log = logging.getLogger(__name__)

#: ``PlanResult.reason`` of a call stopped through :attr:`ArmPlanner.stop`.
CANCELLED = "cancelled"


@dataclass(frozen=True)
class PlannerConfig:
    """``algorithm``: "rrtconnect" or "rrtstar"; ``time_limit`` [s] per attempt;
    ``attempts``; ``range`` [rad] RRT step (0: OMPL's default); ``resolution`` [rad]
    longest joint-space step between two checked states on an edge; ``simplify_time`` [s]
    for OMPL's full simplifier (0: one vertex-reduction pass plus greedy shortcuts, much
    cheaper; < 0: no simplification);
    ``velocity_scale`` in (0, 1] of each joint's limit; ``sample_period`` [s] of the timed
    trajectory; ``seed`` for OMPL's random generator (deterministic planning)."""

    algorithm: str = "rrtconnect"
    time_limit: float = 1.0
    attempts: int = 3
    range: float = 0.0
    resolution: float = 0.04
    simplify_time: float = 0.0
    velocity_scale: float = 0.5
    acceleration_scale: float = 0.5
    sample_period: float = 0.05
    seed: int | None = 0

    def validate(self) -> list[str]:
        errs = []
        if self.algorithm not in ("rrtconnect", "rrtstar"):
            errs.append(f"algorithm: expected 'rrtconnect' or 'rrtstar', got {self.algorithm!r}")
        if not self.time_limit > 0:
            errs.append(f"time_limit: must be > 0 s, got {self.time_limit}")
        if self.attempts < 1:
            errs.append(f"attempts: must be >= 1, got {self.attempts}")
        if not 0 < self.velocity_scale <= 1 or not 0 < self.acceleration_scale <= 1:
            errs.append("velocity_scale and acceleration_scale must be in (0, 1]")
        if not self.resolution > 0 or not self.sample_period > 0:
            errs.append("resolution and sample_period must be > 0")
        return errs


@dataclass(frozen=True)
class PlanResult:
    """``success``; ``reason`` when not ("no IK", "start in collision: ...", "goal in
    collision: ...", "no plan within 1.0 s x 3 attempts", ...); ``planning_time`` [s]
    (wall time spent planning, for logs and benchmarks); ``path`` joint waypoints;
    ``trajectory`` timed for the Arm; ``attempts`` used."""

    success: bool
    reason: str = ""
    planning_time: float = 0.0
    path: list[tuple[float, ...]] = field(default_factory=list)
    trajectory: JointTrajectory | None = None
    attempts: int = 0


#: [rad] waypoints where the path turns by more than this (in the joint space scaled by
#: the velocity limits) are passed at rest; gentler turns (a Cartesian line's dense IK
#: waypoints, a simplified OMPL path's near-collinear points) are passed at speed.
MAX_BLEND_TURN = 0.2
#: share of each joint's acceleration limit kept for the velocity change at a waypoint
#: passed at speed (the rest is the path's own speed-up and slow-down on the segments
#: next to it), so the two together stay within the limit.
BLEND_ACCEL_SHARE = 0.25


def _segment_profile(L: float, v0: float, v1: float, vlim: float, alim: float) -> tuple[float, float, float, float]:
    """Trapezoid along a segment of length ``L`` from speed ``v0`` to ``v1`` (reachable
    from each other with ``alim``): (peak speed, accel time, cruise time, decel time)."""
    vp = min(vlim, math.sqrt(max(0.0, alim * L + 0.5 * (v0 * v0 + v1 * v1))))
    vp = max(vp, v0, v1)
    t1 = (vp - v0) / alim
    t3 = (vp - v1) / alim
    cruise = L - (vp * vp - v0 * v0) / (2 * alim) - (vp * vp - v1 * v1) / (2 * alim)
    t2 = max(0.0, cruise) / vp if vp > 0 else 0.0
    return vp, t1, t2, t3


def _segment_distance(t: float, v0: float, vp: float, v1: float, t1: float, t2: float, t3: float, alim: float) -> float:
    """Distance covered at time ``t`` [s] into the segment's trapezoid."""
    if t <= t1:
        return v0 * t + 0.5 * alim * t * t
    d1 = v0 * t1 + 0.5 * alim * t1 * t1
    if t <= t1 + t2:
        return d1 + vp * (t - t1)
    r = min(t - t1 - t2, t3)
    return d1 + vp * t2 + vp * r - 0.5 * alim * r * r


def time_parametrize(
    joint_names: Sequence[str],
    path: Sequence[Sequence[float]],
    limits: Sequence[JointLimit],
    *,
    velocity_scale: float = 0.5,
    acceleration_scale: float = 0.5,
    sample_period: float = 0.05,
    default_acceleration: float = 2.0,
) -> JointTrajectory:
    """Time ``path`` (joint waypoints, the first being the current position) into a
    :class:`JointTrajectory` that follows the straight joint-space segments between the
    waypoints exactly, all joints synchronised, with no joint above ``velocity_scale`` x
    its velocity limit nor ``acceleration_scale`` x its acceleration limit
    (``default_acceleration`` [rad/s^2] where the limit is infinite).

    The path speed is one profile over the whole path (the forward-backward pass of
    time-optimal path parametrisation, for a piecewise-linear path): it starts
    and ends at rest, is limited per segment by the joints' limits along it, and passes
    a waypoint at the speed whose velocity change across the corner the joints'
    acceleration limits absorb between the samples around it; where the path turns by more than
    ``MAX_BLEND_TURN`` it stops there. So a Cartesian line of dense waypoints runs through
    at speed instead of stopping at each. Samples every ``sample_period`` [s] at most, and
    at every waypoint."""
    if len(path) < 2:
        q = tuple(float(x) for x in path[-1]) if path else ()
        if not q:
            raise ValueError("time_parametrize: empty path")
        return JointTrajectory(tuple(joint_names), (sample_period,), (q,))
    vmax = np.array([lim.velocity for lim in limits], dtype=float) * velocity_scale
    amax = np.array([lim.acceleration if math.isfinite(lim.acceleration) else default_acceleration for lim in limits])
    amax = amax * acceleration_scale
    pts = [np.asarray(path[0], dtype=float)]
    for q in path[1:]:
        q = np.asarray(q, dtype=float)
        if np.any(np.abs(q - pts[-1]) > 1e-12):
            pts.append(q)
    if len(pts) < 2:
        return JointTrajectory(tuple(joint_names), (sample_period,), (tuple(float(x) for x in path[-1]),))
    deltas = [b - a for a, b in pairwise(pts)]
    lengths = [float(np.linalg.norm(d)) for d in deltas]
    dirs = [d / L for d, L in zip(deltas, lengths)]
    with np.errstate(divide="ignore"):
        vlims = [float(np.min(np.where(np.abs(u) > 1e-12, vmax / np.abs(u), np.inf))) for u in dirs]
        alims = [float(np.min(np.where(np.abs(u) > 1e-12, amax / np.abs(u), np.inf))) for u in dirs]
    # speed limit at each waypoint: 0 at both ends and at sharp turns
    n = len(pts)
    vcap = [0.0] * n
    for k in range(1, n - 1):
        u0, u1 = dirs[k - 1], dirs[k]
        s0, s1 = u0 / vmax, u1 / vmax  # directions in the velocity-limit-scaled space
        cos_turn = float(s0 @ s1 / (np.linalg.norm(s0) * np.linalg.norm(s1)))
        if math.acos(max(-1.0, min(1.0, cos_turn))) > MAX_BLEND_TURN:
            continue
        # the velocity jump v |u1 - u0| spreads over the samples either side of the
        # waypoint: at least half a sample period apart, or the shorter segment's
        # traversal time when that is less (dense waypoints)
        jump = np.abs(u1 - u0)
        short = min(lengths[k - 1], lengths[k])
        ab = BLEND_ACCEL_SHARE * amax
        with np.errstate(divide="ignore"):
            vj = float(np.min(np.where(jump > 1e-12, np.minimum(0.5 * ab * sample_period / jump,
                                                                  np.sqrt(ab * short / jump)), np.inf)))
        vcap[k] = min(vlims[k - 1], vlims[k], vj)
    # segments touching a waypoint passed at speed leave that share to the corner
    for k in range(n - 1):
        if vcap[k] > 0 or vcap[k + 1] > 0:
            alims[k] *= 1.0 - BLEND_ACCEL_SHARE
    # forward-backward pass: reachable from the start and able to stop by the end
    v = vcap[:]
    for k in range(1, n):
        v[k] = min(v[k], math.sqrt(v[k - 1] ** 2 + 2 * alims[k - 1] * lengths[k - 1]))
    for k in range(n - 2, -1, -1):
        v[k] = min(v[k], math.sqrt(v[k + 1] ** 2 + 2 * alims[k] * lengths[k]))
    times: list[float] = []
    points: list[tuple[float, ...]] = []
    t0 = 0.0
    for k in range(n - 1):
        L, a = lengths[k], alims[k]
        vp, t1, t2, t3 = _segment_profile(L, v[k], v[k + 1], vlims[k], a)
        T = max(t1 + t2 + t3, 1e-6)
        m = max(1, math.ceil(T / sample_period - 1e-9))
        for i in range(1, m + 1):
            t = T * i / m
            d = L if i == m else min(L, _segment_distance(t, v[k], vp, v[k + 1], t1, t2, t3, a))
            times.append(t0 + t)
            points.append(tuple(float(x) for x in pts[k] + dirs[k] * d))
        t0 += T
    return JointTrajectory(tuple(joint_names), tuple(times), tuple(points))


class ArmPlanner:
    """Plans for the arm of ``scene`` with kinematics ``kin`` (joint order must match)."""

    def __init__(self, scene: PlanningScene, kin: ArmKinematics, config: PlannerConfig | None = None) -> None:
        if tuple(scene.model.arm_joints) != tuple(kin.joint_names):
            raise ValueError(
                f"planner: scene joints {scene.model.arm_joints} differ from kinematics joints {kin.joint_names}"
            )
        self.scene = scene
        self.kin = kin
        self.config = config or PlannerConfig()
        #: set (from any thread) to make the running plan call return "cancelled" early;
        #: the caller clears it before the next call
        self.stop = threading.Event()
        errs = self.config.validate()
        if errs:
            raise ValueError("PlannerConfig: " + "; ".join(errs))

    # ------------------------------------------------------------------ joint goals
    def plan(self, q_start: Sequence[float], q_goal: Sequence[float], config: PlannerConfig | None = None) -> PlanResult:
        """Collision-free joint path from ``q_start`` to ``q_goal`` [rad], timed."""
        cfg = config or self.config
        t_begin = time.perf_counter()
        scene = self.scene
        if not scene.is_valid(q_start):
            return PlanResult(False, f"start in collision: {_pairs(scene.collisions(q_start)) or 'outside joint limits'}",
                              time.perf_counter() - t_begin)
        if not scene.is_valid(q_goal):
            return PlanResult(False, f"goal in collision: {_pairs(scene.collisions(q_goal)) or 'outside joint limits'}",
                              time.perf_counter() - t_begin)
        path: list[tuple[float, ...]] | None = None
        used = 0
        if self._motion_valid(q_start, q_goal, cfg.resolution):
            path = [tuple(map(float, q_start)), tuple(map(float, q_goal))]
        else:
            for attempt in range(cfg.attempts):
                if self.stop.is_set():
                    break
                used = attempt + 1
                path = self._ompl(q_start, q_goal, cfg, attempt)
                if path is not None:
                    break
        elapsed = time.perf_counter() - t_begin
        if path is None and self.stop.is_set():
            return PlanResult(False, CANCELLED, elapsed, attempts=used)
        if path is None:
            return PlanResult(False, f"no plan within {cfg.time_limit:g} s x {cfg.attempts} attempts", elapsed, attempts=used)
        traj = time_parametrize(self.kin.joint_names, path, self.kin.limits,
                                velocity_scale=cfg.velocity_scale, acceleration_scale=cfg.acceleration_scale,
                                sample_period=cfg.sample_period)
        return PlanResult(True, "", elapsed, path, traj, used)

    def _motion_valid(self, a: Sequence[float], b: Sequence[float], resolution: float) -> bool:
        qa, qb = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
        n = max(1, math.ceil(float(np.max(np.abs(qb - qa))) / resolution))
        return all(self.scene.is_valid(qa + (qb - qa) * k / n) for k in range(1, n + 1))

    def _ompl(self, q_start: Sequence[float], q_goal: Sequence[float], cfg: PlannerConfig, attempt: int) -> list[tuple[float, ...]] | None:
        n = self.kin.dof
        ss, si = ompl_setup(self.scene.limits, self.scene.is_valid, resolution=cfg.resolution, seed=cfg.seed,
                            algorithm=cfg.algorithm, step=cfg.range)
        ss.setStartAndGoalStates(ompl_state(si, q_start), ompl_state(si, q_goal))
        if not ompl_solve(ss, cfg.time_limit, self.stop):
            return None
        sol = ss.getSolutionPath()
        raw = [tuple(float(st[i]) for i in range(n)) for st in sol.getStates()]
        if cfg.simplify_time > 0:
            ss.simplifySolution(cfg.simplify_time)
        elif cfg.simplify_time == 0:
            # cheap: one pass of OMPL's vertex reduction, then greedy shortcuts (ours)
            ss.getPathSimplifier().reduceVertices(sol, len(raw) * 2)
        path = [tuple(float(st[i]) for i in range(n)) for st in ss.getSolutionPath().getStates()]
        if cfg.simplify_time == 0:
            path = self._shortcut(path, cfg.resolution)
        # OMPL interpolates edges by Euclidean distance, we by the largest joint step:
        # a thin obstacle can fall between the samples of one and not the other
        if not all(self._motion_valid(a, b, cfg.resolution) for a, b in pairwise(path)):
            if all(self._motion_valid(a, b, cfg.resolution) for a, b in pairwise(raw)):
                return raw
            log.info("planner: path failed re-validation at %.3f rad; next attempt", cfg.resolution)
            return None
        return path

    def _shortcut(self, path: list[tuple[float, ...]], resolution: float) -> list[tuple[float, ...]]:
        """Greedy shortcutting: from each kept waypoint jump to the farthest one reachable
        by a collision-free straight joint-space motion."""
        if len(path) <= 2:
            return path
        out = [path[0]]
        i = 0
        while i < len(path) - 1:
            j = len(path) - 1
            while j > i + 1 and not self._motion_valid(path[i], path[j], resolution):
                j -= 1
            out.append(path[j])
            i = j
        return out

    # ------------------------------------------------------------------ pose goals
    def plan_to_pose(
        self,
        q_start: Sequence[float],
        T_target: np.ndarray,
        *,
        free_approach_rotation: bool = False,
        ik_attempts: int = 20,
        ik_seeds: Sequence[Sequence[float]] = (),
        config: PlannerConfig | None = None,
    ) -> PlanResult:
        """Plan to a tool pose ``T_target`` (4x4 in the arm base): a collision-free IK
        solution then :meth:`plan`. IK starts from each of ``ik_seeds`` [rad] in order
        (a nominal posture picks the solution family: elbow up, wrist not flipped), then
        from ``q_start`` and seeded random configurations."""
        t0 = time.perf_counter()
        q_goal = None
        for s in ik_seeds:
            q_goal = self.kin.ik(T_target, s, free_approach_rotation=free_approach_rotation, attempts=1,
                                 is_valid=self.scene.is_valid)
            if q_goal is not None or self.stop.is_set():
                break
        if self.stop.is_set():
            return PlanResult(False, CANCELLED, time.perf_counter() - t0)
        if q_goal is None:
            q_goal = self.kin.ik(T_target, q_start, free_approach_rotation=free_approach_rotation,
                                 attempts=ik_attempts, is_valid=self.scene.is_valid)
        if q_goal is None:
            reason = "no IK" if self.kin.ik(T_target, q_start, free_approach_rotation=free_approach_rotation,
                                             attempts=ik_attempts) is None else "no collision-free IK"
            return PlanResult(False, reason, time.perf_counter() - t0)
        r = self.plan(q_start, q_goal, config)
        return PlanResult(r.success, r.reason, time.perf_counter() - t0, r.path, r.trajectory, r.attempts)

    def cartesian_path(
        self,
        q_start: Sequence[float],
        T_goal: np.ndarray,
        *,
        step: float = 0.01,
        max_joint_step: float = 0.25,
        free_approach_rotation: bool = False,
        config: PlannerConfig | None = None,
    ) -> PlanResult:
        """Straight tool line from the pose at ``q_start`` to ``T_goal`` (4x4, arm base):
        positions interpolated linearly every ``step`` [m], rotations by slerp, IK per
        waypoint seeded by the previous one. Fails when a waypoint has no IK, a joint
        jumps more than ``max_joint_step`` [rad] between waypoints, or a motion collides."""
        cfg = config or self.config
        t0 = time.perf_counter()

        q = np.asarray(q_start, dtype=float)
        if not self.scene.is_valid(q):
            return PlanResult(False, f"start in collision: {_pairs(self.scene.collisions(q))}", time.perf_counter() - t0)
        T0 = self.kin.fk(q)
        T1 = np.asarray(T_goal, dtype=float)
        dist = float(np.linalg.norm(T1[:3, 3] - T0[:3, 3]))
        q0, q1 = matrix_to_quat(T0[:3, :3]), matrix_to_quat(T1[:3, :3])
        if np.dot(q0, q1) < 0:
            q1 = -q1
        ang = math.acos(min(1.0, abs(float(np.dot(q0, q1))))) * 2
        n = max(1, math.ceil(max(dist / step, ang / 0.05)))
        path = [tuple(q)]
        for k in range(1, n + 1):
            if self.stop.is_set():
                return PlanResult(False, CANCELLED, time.perf_counter() - t0)
            s = k / n
            T = np.eye(4)
            T[:3, 3] = T0[:3, 3] + s * (T1[:3, 3] - T0[:3, 3])
            T[:3, :3] = quat_to_matrix(_slerp(q0, q1, s))
            qn = self.kin.ik(T, q, free_approach_rotation=free_approach_rotation, attempts=1, max_iterations=60)
            if qn is None:
                return PlanResult(False, f"no IK at {100 * s:.0f} % of the straight line", time.perf_counter() - t0)
            if float(np.max(np.abs(qn - q))) > max_joint_step:
                return PlanResult(False, f"joint jump at {100 * s:.0f} % of the straight line", time.perf_counter() - t0)
            if not self._motion_valid(q, qn, cfg.resolution):
                hit = _pairs(self.scene.collisions(qn))
                return PlanResult(False, f"straight line in collision at {100 * s:.0f} %: {hit}", time.perf_counter() - t0)
            path.append(tuple(float(x) for x in qn))
            q = qn
        traj = time_parametrize(self.kin.joint_names, path, self.kin.limits,
                                velocity_scale=cfg.velocity_scale, acceleration_scale=cfg.acceleration_scale,
                                sample_period=cfg.sample_period)
        return PlanResult(True, "", time.perf_counter() - t0, path, traj, 1)


def ompl_setup(limits: Sequence[tuple[float, float]], is_valid: Callable[[list[float]], bool], *, resolution: float,
               seed: int | None, algorithm: str, step: float = 0.0) -> tuple[Any, Any]:
    """An OMPL ``SimpleSetup`` over the box ``limits`` ((low, high) per coordinate) whose
    states are valid when ``is_valid`` (called with the coordinates as a list) says so,
    edges checked every ``resolution`` (Euclidean over all coordinates), and its
    planner: "rrtconnect", or "rrtstar" stopped at its first solution; ``step`` the
    planner's range (0: OMPL's default). Returns ``(setup, space information)``; set the
    start and goal, then :func:`ompl_solve`."""
    from ompl import base as ob
    from ompl import geometric as og
    from ompl import util as ou

    ou.setLogLevel(ou.LogLevel.LOG_WARN)
    _seed_ompl_once(seed)
    n = len(limits)
    space = ob.RealVectorStateSpace(n)
    bounds = ob.RealVectorBounds(n)
    for i, (lo, hi) in enumerate(limits):
        bounds.setLow(i, float(lo))
        bounds.setHigh(i, float(hi))
    space.setBounds(bounds)
    ss = og.SimpleSetup(space)

    def check(s: Any) -> bool:
        return is_valid([s[i] for i in range(n)])

    ss.setStateValidityChecker(check)
    si = ss.getSpaceInformation()
    si.setStateValidityCheckingResolution(resolution / si.getMaximumExtent())
    if algorithm == "rrtstar":
        planner = og.RRTstar(si)
        obj = ob.PathLengthOptimizationObjective(si)
        obj.setCostThreshold(ob.Cost(math.inf))  # stop at the first solution
        ss.setOptimizationObjective(obj)
    else:
        planner = og.RRTConnect(si)
    if step > 0:
        planner.setRange(step)
    ss.setPlanner(planner)
    return ss, si


def ompl_state(si: Any, values: Sequence[float]) -> Any:
    """A new OMPL state of space information ``si`` holding ``values``."""
    st = si.allocState()
    for i, v in enumerate(values):
        st[i] = float(v)
    return st


def ompl_solve(ss: Any, time_limit: float, stop: threading.Event) -> bool:
    """Run the setup's planner for at most ``time_limit`` [s], or until ``stop`` is set;
    True for an exact solution (``ss.getSolutionPath()``)."""
    from ompl import base as ob

    ptc = ob.plannerOrTerminationCondition(ob.timedPlannerTerminationCondition(time_limit),
                                           ob.PlannerTerminationCondition(stop.is_set))
    return bool(ss.solve(ptc).getStatus() == ob.PlannerStatus.EXACT_SOLUTION)


_OMPL_SEEDED: list[int] = []


def _seed_ompl_once(seed: int | None) -> None:
    """OMPL's global generator can be seeded only before its first use in the process;
    later calls would just print an error. So the first planner seeds it, and runs are
    deterministic for a given process-wide sequence of queries."""
    if seed is None or _OMPL_SEEDED:
        return
    from ompl import util as ou

    ou.RNG.setSeed(int(seed) + 1)
    _OMPL_SEEDED.append(int(seed))


def _slerp(q0: np.ndarray, q1: np.ndarray, s: float) -> np.ndarray:
    d = float(np.clip(np.dot(q0, q1), -1.0, 1.0))
    if d > 0.9995:
        q = q0 + s * (q1 - q0)
        return q / np.linalg.norm(q)
    th = math.acos(d)
    return (math.sin((1 - s) * th) * q0 + math.sin(s * th) * q1) / math.sin(th)


def _pairs(pairs: list[tuple[str, str]]) -> str:
    return ", ".join(f"{a} vs {b}" for a, b in pairs[:3]) + (" ..." if len(pairs) > 3 else "")
