"""Holistic base+arm planning benchmark: 50 seeded queries whose front stand-off is blocked.

Scenes are the ``lab`` world (sim/worlds/lab.yaml) at its nominal poses plus one blocking
obstacle each, built here: a target in a shelf compartment (front grasp: the seed's
pre-grasp 10 cm out along the face normal, the grasp 3 cm behind the face) or on the
table (top grasp: pre-grasp 10 cm above, the approach straight down), and a low box
(15-24 cm high, below the lowest board) on the floor in front of it, placed so that no
stand-off the robot's profile would drive to (``nav.approach_distances`` along the
normal, 0 and +-10 degrees, as ``approach`` tries them) is free in the inflated map:
checked with :func:`mmexec.skills.navigation.standoff.find_standoff`, a scene where one
is free is drawn again. The robot starts 1-2.5 m away at a free pose in the same free
region, the arm in its stow pose.

Per query: the holistic planner (:mod:`mmexec.skills.manipulation.holistic`, RRT-Connect,
1 s x 5 attempts unless told otherwise) plans the 9-D robot to the pre-grasp; a solution
is checked (base pose free in the inflated map and reached by A* from the start, the
arm's forward kinematics at the pre-grasp within 1 mm, the state collision-free). Then
the arm-only part as the skill runs it: the base "arrives" with a navigation error (2 cm,
0.02 rad standard deviations) and RRT-Connect (1 s x 5) re-plans the arm from the stow
pose to the pre-grasp from there (the paper: RRT* 5 x 15 s for the holistic plan,
RRT-Connect 5 x 10 s for the arm). ``--rrtstar N`` also runs RRT* (to its first
solution) on the first N queries of each robot.

    .venv/bin/python benchmarks/holistic.py [--queries 50] [--seed 0] [--rrtstar 20] [-v]

Last line: ``holistic_plan_median_ms: X`` (RRT-Connect, all robots' queries).
"""

from __future__ import annotations

import argparse
import itertools
import math
import os
import platform
import statistics
import time
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from mmexec.config.yamlload import load_yaml
from mmexec.drivers.descriptions import get
from mmexec.drivers.interfaces import Pose2D
from mmexec.sim.world import Obstacle, World, load_world
from mmexec.skills.manipulation.grasp import grasp_poses
from mmexec.skills.manipulation.holistic import (
    HolisticConfig,
    HolisticModel,
    HolisticPlanner,
    replan_arm,
)
from mmexec.skills.manipulation.planner import ArmPlanner, PlannerConfig, PlanResult
from mmexec.skills.navigation.astar import plan_path
from mmexec.skills.navigation.grid import CostMap, inflate, world_to_cell
from mmexec.skills.navigation.standoff import find_standoff

REPO = Path(__file__).resolve().parents[1]
#: robot -> its sim config (stow and reach postures, approach distances, grasp height) and
#: whether it grasps table objects from above: the WX250s cannot point its gripper down
#: at the table top (the pre-grasp lies 0.47 m above its mount, which the arm reaches only
#: straight up over the shoulder), so it takes them from the front like shelf items
CONFIGS = {"locobot_wx250s": ("config/locobot_sim.yaml", False), "ur5e_robotiq": ("config/ur5e_sim.yaml", True)}
MARGIN = 0.03  # m, nav.margin of both configs


@dataclass(frozen=True)
class Robot:
    name: str
    stow: tuple[float, ...]
    seeds: list[tuple[float, ...]]
    distances: list[float]
    grasp_height: float
    top_grasp: bool  # table objects from above (else from the front, like shelf items)


def robot_profile(name: str) -> Robot:
    """The robot's postures and stand-off distances from its shipped sim config."""
    path, top = CONFIGS[name]
    prof = load_yaml(REPO / path)["profile"]
    poses = prof["named_poses"]
    arm = prof["arm"]
    seeds = [tuple(poses[arm["reach"]])] if arm.get("reach") else []
    seeds.append(tuple(poses["home"]))
    return Robot(name, tuple(poses[arm.get("stow", "sleep")]), seeds, list(prof["nav"]["approach_distances"]),
                 float(prof["fetch"].get("grasp_height", 0.0)), top)


@dataclass(frozen=True)
class Query:
    kind: str                 # "shelf" (front grasp) or "table" (top grasp)
    world: World
    costmap: CostMap
    start: Pose2D
    pre_grasp: np.ndarray     # T_map_tool
    grasp: np.ndarray


def _frame(origin: np.ndarray, z: np.ndarray, y: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, 2], T[:3, 1] = z, y
    T[:3, 0] = np.cross(y, z)
    T[:3, 3] = origin
    return T


def _targets(world: World, top: bool, rng: np.random.Generator) -> tuple[str, np.ndarray, np.ndarray]:
    """A target: kind, the grasp frame in map (marker convention: z out of the face
    towards the gripper, y up; a top grasp: z up, x the fingers' travel) and the frame
    of the face the robot would stand in front of (z its horizontal outward normal: the
    grasp frame itself on a shelf, the table's edge in front of a table object)."""
    spec = world.spec
    up = np.array([0.0, 0.0, 1.0])
    if rng.uniform() < 0.6:
        sh = spec.shelves[int(rng.integers(len(spec.shelves)))]
        board = float(sh.boards[int(rng.integers(len(sh.boards)))])
        c, s = math.cos(sh.pose[2]), math.sin(sh.pose[2])
        u = rng.uniform(-(sh.width / 2 - 0.14), sh.width / 2 - 0.14)
        lx = sh.depth / 2 - 0.06  # the item's front face 6 cm inside the shelf front
        origin = np.array([sh.pose[0] + c * lx - s * u, sh.pose[1] + s * lx + c * u, board + 0.03])
        T = _frame(origin, np.array([c, s, 0.0]), up)
        return "shelf", T, T
    tb = spec.tables[0]
    c, s = math.cos(tb.pose[2]), math.sin(tb.pose[2])
    lx, ly = rng.uniform(-tb.size[0] / 2 + 0.1, tb.size[0] / 2 - 0.1), tb.size[1] / 2 - rng.uniform(0.08, 0.2)
    centre = np.array([tb.pose[0] + c * lx - s * ly, tb.pose[1] + s * lx + c * ly, tb.size[2] + 0.03])
    n = np.array([-s, c, 0.0])  # the table's +y edge faces the room (its -y edge is at the wall)
    edge = np.array([tb.pose[0] + c * lx - s * tb.size[1] / 2, tb.pose[1] + s * lx + c * tb.size[1] / 2, centre[2]])
    face = _frame(edge, n, up)
    if not top:  # from the front: the marker-like frame on the object's face towards the room
        return "table", _frame(centre + 0.03 * n, n, up), face
    yaw = rng.uniform(-math.pi / 2, math.pi / 2)
    x = np.array([math.cos(yaw), math.sin(yaw), 0.0])  # fingers' travel
    return "table", _frame(centre, up, np.cross(up, x)), face


def _picked_from_front(model: HolisticModel, robot: Robot, T_face: np.ndarray, pre: np.ndarray, grasp: np.ndarray,
                       world: World, cm: CostMap) -> bool:
    """Whether ``robot`` picks the target from its front stand-off while nothing blocks
    it, as the fetch mission's approach and pick would: a stand-off of its profile (on
    the face normal) is free in ``cm``, and from there the arm has a collision-free IK
    for the pre-grasp ``pre`` and, near it, for the ``grasp`` (both 4x4 in map)."""
    model.use_map(cm)
    model.prepare(world.scene_boxes())
    try:
        for d in robot.distances:
            found = find_standoff(cm, T_face, [d], angle_offsets=(0.0,))
            if found.pose is None:
                continue
            b = found.pose
            T_am = np.linalg.inv(model.T_map_armbase(b.x, b.y, b.theta))
            model.scene.place_root(b.x, b.y, b.theta)
            for seed in robot.seeds:
                q = model.kin.ik(T_am @ pre, seed, attempts=5, is_valid=model.scene.is_valid)
                if q is not None and model.kin.ik(T_am @ grasp, q, attempts=1, is_valid=model.scene.is_valid) is not None:
                    return True
        return False
    finally:
        model.release()


def make_query(robot: Robot, model: HolisticModel, rng: np.random.Generator) -> Query:
    """One blocked-front query for ``robot`` (see the module doc): a target it picks from
    its front stand-off in the lab as it is, and a blocker whose far side lies where the
    farthest stand-off's footprint circle would reach, give or take."""
    base = load_world("lab")
    radius = model.description.info.footprint_radius
    cm0 = inflate(base.occupancy(0.05), radius, MARGIN)
    reach = max(robot.distances) - radius - MARGIN  # a far side beyond this blocks every stand-off
    for _ in range(200):
        kind, T_grasp, T_face = _targets(base, robot.top_grasp, rng)
        if kind == "table" and robot.top_grasp:
            poses = grasp_poses(T_grasp, _axis(robot), pre_grasp=(0.0, 0.0, 0.10))
        else:
            poses = grasp_poses(T_grasp, _axis(robot), pre_grasp=(0.0, 0.0, 0.10), grasp_depth=0.03,
                                grasp_height=robot.grasp_height)
        if not _picked_from_front(model, robot, T_face, poses.pre_grasp, poses.grasp, base, cm0):
            continue  # not a target the robot picks from the front anyway
        n = T_face[:3, 2]
        depth, width, height = rng.uniform(0.2, 0.3), rng.uniform(0.3, 0.5), rng.uniform(0.15, 0.24)
        far = max(reach + rng.uniform(0.03, 0.15), depth + 0.05)  # its near side at least 5 cm from the face
        d = far - depth / 2
        lateral = rng.uniform(-0.05, 0.05)
        cx = T_face[0, 3] + d * n[0] - lateral * n[1]
        cy = T_face[1, 3] + d * n[1] + lateral * n[0]
        blocker = Obstacle("blocker", (float(cx), float(cy), math.atan2(n[1], n[0])), (depth, width, height))
        world = load_world("lab", extra_obstacles=(blocker,))
        cm = inflate(world.occupancy(0.05), radius, MARGIN)
        front = find_standoff(cm, T_face, robot.distances, angle_offsets=(0.0, math.radians(10), -math.radians(10)))
        if front.ok:
            continue  # the front is not blocked: draw again
        start = _start(cm, T_grasp[:3, 3], rng)
        if start is None:
            continue
        return Query(kind, world, cm, start, poses.pre_grasp, poses.grasp)
    raise RuntimeError("could not build a blocked-front query")


def _axis(robot: Robot) -> int:
    arm = get(robot.name).arm
    assert arm is not None
    return arm.approach_axis


def _start(cm: CostMap, target: np.ndarray, rng: np.random.Generator) -> Pose2D | None:
    """A free pose 1-2.5 m from the target in the room's largest free region."""
    labels = cv2.connectedComponents((~cm.blocked).astype(np.uint8), connectivity=4)[1]
    main = int(np.argmax(np.bincount(labels[labels > 0]))) if (labels > 0).any() else 0
    for _ in range(200):
        r, a = rng.uniform(1.0, 2.5), rng.uniform(-math.pi, math.pi)
        x, y = target[0] + r * math.cos(a), target[1] + r * math.sin(a)
        row, col = world_to_cell(cm.grid, x, y)
        if cm.in_bounds(row, col) and not cm.blocked[row, col] and labels[row, col] == main:
            return Pose2D(x, y, rng.uniform(-math.pi, math.pi))
    return None


@dataclass
class Outcome:
    ok: bool
    ms: float
    reason: str = ""
    arm_ok: bool = False
    arm_ms: float = 0.0
    drive: float = 0.0
    dense: bool | None = None  # a failure re-run with the dense search: solved?
    rounds: int = 0  # holistic plans until the arm re-plan succeeded (the skill's rounds)
    cpu_ms: float = 0.0
    attempts: int = 0
    tolerant: bool = True


#: The dense search a failure is re-run with: 10 x the goal candidates, no navigation
#: tolerance, 3 attempts (does the query have a solution at all?)
DENSE = HolisticConfig(goal_candidates=3000, goal_count=6, attempts=3, tolerance=(0.0, 0.0), drive_margin=(0.0, 0.0),
                       time_limit=2.0)


def _arrive_and_replan(model: HolisticModel, planner: HolisticPlanner, arm: ArmPlanner, robot: Robot, q: Query,
                       goal: Pose2D, goal_arm: tuple[float, ...], rng: np.random.Generator) -> tuple[PlanResult, int]:
    """The base stops near ``goal`` (2 cm, 0.02 rad standard deviations, in the free
    space of the inflated map) and the arm is
    re-planned from the stow pose there; a failure plans the whole robot again from the
    pose reached (the skill's second round). The last arm plan and the rounds used."""
    mount = model.description.arm_mount
    for rounds in (1, 2):
        reached = goal
        for _ in range(100):  # navigation stops in free space: no arrival inside an obstacle's inflation
            reached = Pose2D(goal.x + rng.normal(0, 0.02), goal.y + rng.normal(0, 0.02),
                             goal.theta + rng.normal(0, 0.02))
            if q.costmap.is_free(reached.x, reached.y):
                break
        a = replan_arm(arm, reached, mount, robot.stow, q.pre_grasp, q.world.scene_boxes(), seeds=[goal_arm, *robot.seeds])
        if a.success or rounds == 2:
            return a, rounds
        model.prepare(q.world.scene_boxes())
        again = planner.plan(reached, robot.stow, q.pre_grasp, T_map_grasp=q.grasp, seeds=robot.seeds)
        model.release()
        if not again.success or again.base_pose is None or again.arm is None:
            return PlanResult(False, f"second round: {again.reason}"), rounds
        goal, goal_arm = again.base_pose, again.arm
    raise AssertionError("unreachable")


def run_robot(robot: Robot, queries: int, seed: int, algorithm: str, time_limit: float, attempts: int,
              count: int | None, verbose: bool, recheck: bool = True) -> list[Outcome]:
    desc = get(robot.name)
    rng = np.random.default_rng(seed)
    model = HolisticModel.build(desc, inflate(load_world("lab").occupancy(0.05), desc.info.footprint_radius, MARGIN))
    qs = [make_query(robot, model, rng) for _ in range(queries)][:count]
    planner = HolisticPlanner(model, HolisticConfig(algorithm=algorithm, time_limit=time_limit, attempts=attempts,
                                                    seed=seed))
    arm = ArmPlanner(model.scene, model.kin, PlannerConfig(time_limit=1.0, attempts=5, seed=seed))
    out = []
    try:
        for i, q in enumerate(qs):
            model.use_map(q.costmap)
            model.prepare(q.world.scene_boxes())
            t, c = time.perf_counter(), time.process_time()
            r = planner.plan(q.start, robot.stow, q.pre_grasp, T_map_grasp=q.grasp, seeds=robot.seeds)
            ms, cpu = (time.perf_counter() - t) * 1e3, (time.process_time() - c) * 1e3
            o = Outcome(r.success, ms, r.reason, cpu_ms=cpu, attempts=r.attempts, tolerant=r.tolerant)
            if r.success:
                assert r.base_pose is not None and r.arm is not None
                state = (r.base_pose.x, r.base_pose.y, r.base_pose.theta, *r.arm)
                err = float(np.linalg.norm(model.tool_pose(state)[:3, 3] - q.pre_grasp[:3, 3]))
                path = plan_path(q.costmap, (q.start.x, q.start.y), (r.base_pose.x, r.base_pose.y))
                if err > 1e-3 or not model.is_valid(state) or path is None:
                    o = Outcome(False, ms, f"bad solution: fk error {err * 1e3:.1f} mm, A* path {path is not None}",
                                cpu_ms=cpu)
                else:
                    o.drive = float(sum(math.dist(a, b) for a, b in itertools.pairwise(path)))
                    # the base stops near, not at, the planned pose: re-plan the arm from there; when
                    # that fails, plan the whole robot again from there and drive again (the skill's
                    # second round)
                    model.release()
                    a, o.rounds = _arrive_and_replan(model, planner, arm, robot, q, r.base_pose, r.arm, rng)
                    o.arm_ok, o.arm_ms = a.success, a.planning_time * 1e3
                    if not a.success:
                        o.reason = f"arm re-plan: {a.reason}"
            model.release()
            if not o.ok and not o.reason.startswith("bad solution") and "arm re-plan" not in o.reason and recheck:
                # is there a solution at all? a 10x denser goal search without the navigation tolerance
                model.prepare(q.world.scene_boxes())
                dense = planner.plan(q.start, robot.stow, q.pre_grasp, T_map_grasp=q.grasp, seeds=robot.seeds,
                                     config=DENSE)
                model.release()
                o.dense = dense.success
            out.append(o)
            if verbose:
                dense = "" if o.dense is None else f" [dense search: {'solved' if o.dense else 'none'}]"
                print(f"{robot.name} {algorithm} query {i:2d} {q.kind:5s}: {'ok ' if o.ok else 'FAIL'} {o.ms:7.1f} ms "
                      f"(CPU {o.cpu_ms:6.1f}) "
                      f"drive {o.drive:4.2f} m; arm {'ok ' if o.arm_ok else '-- '} {o.arm_ms:6.1f} ms {o.reason}{dense}")
    finally:
        model.close()
    return out


def _summary(name: str, res: list[Outcome]) -> str:
    ok = [o for o in res if o.ok]
    ms = [o.ms for o in res]
    arm = [o.arm_ms for o in ok if o.arm_ok]
    cpu = [o.cpu_ms for o in res]
    line = (f"{name}: solved {len(ok)}/{len(res)} ({100.0 * len(ok) / len(res):.0f} %), planning ms median "
            f"{statistics.median(ms):.0f}, p90 {sorted(ms)[max(0, int(0.9 * len(ms)) - 1)]:.0f}, max {max(ms):.0f} "
            f"(CPU median {statistics.median(cpu):.0f}); first attempt {sum(o.attempts == 1 for o in ok)}, "
            f"without the navigation tolerance {sum(not o.tolerant for o in ok)}")
    if ok:
        line += f"; drive median {statistics.median(o.drive for o in ok):.2f} m"
    if arm:
        line += (f"; arm re-plan (RRT-Connect) {len(arm)}/{len(ok)} ({sum(o.rounds == 2 for o in ok)} in the second "
                 f"round), median {statistics.median(arm):.0f} ms, max {max(arm):.0f} ms")
    checked = [o for o in res if o.dense is not None]
    if checked:
        found = sum(bool(o.dense) for o in checked)
        line += (f"; of {len(checked)} failures re-run with the dense search, {found} solved there "
                 f"(so {len(ok)}/{len(res) - len(checked) + found} of the queries with a known solution)")
    return line


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--queries", type=int, default=50)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--robots", default="locobot_wx250s,ur5e_robotiq")
    ap.add_argument("--time-limit", type=float, default=1.0)
    ap.add_argument("--attempts", type=int, default=5)
    ap.add_argument("--rrtstar", type=int, default=0, metavar="N", help="also RRT* on the first N queries")
    ap.add_argument("-v", "--verbose", action="store_true")
    args = ap.parse_args(argv)
    print(f"machine: {platform.machine()} {platform.processor() or ''} python {platform.python_version()}, "
          f"load average at start {os.getloadavg()[0]:.1f}")
    all_ms: list[float] = []
    for name in args.robots.split(","):
        robot = robot_profile(name)
        res = run_robot(robot, args.queries, args.seed, "rrtconnect", args.time_limit, args.attempts, None, args.verbose)
        all_ms += [o.ms for o in res]
        print(_summary(f"{name} holistic RRT-Connect {args.time_limit:g} s x {args.attempts}", res))
        fails = [o.reason for o in res if not o.ok]
        for reason in sorted(set(fails)):
            print(f"  failed {fails.count(reason)}x: {reason}")
        if args.rrtstar:
            star = run_robot(robot, args.queries, args.seed, "rrtstar", args.time_limit, args.attempts, args.rrtstar,
                             args.verbose, recheck=False)
            print(_summary(f"{name} holistic RRT* (first solution) {args.time_limit:g} s x {args.attempts}", star))
    print(f"load average at the end {os.getloadavg()[0]:.1f}")
    print(f"holistic_plan_median_ms: {statistics.median(all_ms):.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
