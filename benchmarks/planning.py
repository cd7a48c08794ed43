"""Arm planning benchmark: RRTConnect on the WX250s shelf pick scene.

A shelf (two compartments: bottom, middle and top boards, two sides and a back panel)
stands in front of the LoCoBot's arm; 50 seeded queries each pick a grasp position inside
a compartment (gripper horizontal, pointing into the shelf), solve a collision-free IK,
and plan from the arm's home pose with RRTConnect (1 s x 3 attempts). Prints one line
per query in verbose mode, a summary, and LAST ``arm_plan_median_ms: X``.

    .venv/bin/python benchmarks/planning.py [--queries 50] [--seed 0] [--algorithm rrtconnect] [-v]
"""

from __future__ import annotations

import argparse
import platform
import statistics
import sys

import numpy as np

from mmexec.drivers.interfaces import SceneBox
from mmexec.skills.manipulation.kinematics import wx250s
from mmexec.skills.manipulation.planner import ArmPlanner, PlannerConfig
from mmexec.skills.manipulation.scene import ArmModel, PlanningScene

HOME = (0.0, -0.4, 0.6, 0.0, 1.2, 0.0)  # folded in front of the base, gripper pointing down-forward


def _box(name: str, centre: tuple[float, float, float], size: tuple[float, float, float]) -> SceneBox:
    T = np.eye(4)
    T[:3, 3] = centre
    return SceneBox(name, T, size)


def shelf_boxes(x_front: float = 0.30, depth: float = 0.25, width: float = 0.50,
                boards: tuple[float, ...] = (-0.02, 0.17, 0.37), t: float = 0.02) -> list[SceneBox]:
    """Shelf in the arm base frame: front edge at ``x_front`` [m], boards at heights
    ``boards`` [m] (top faces), ``width`` along y, side panels and a back panel."""
    cx = x_front + depth / 2
    top = boards[-1] + t
    bottom = boards[0] - t
    out = [_box(f"board_{i}", (cx, 0.0, z - t / 2), (depth, width, t)) for i, z in enumerate(boards)]
    h = top - bottom
    out.append(_box("side_left", (cx, width / 2 + t / 2, bottom + h / 2), (depth, t, h)))
    out.append(_box("side_right", (cx, -width / 2 - t / 2, bottom + h / 2), (depth, t, h)))
    out.append(_box("back", (x_front + depth + t / 2, 0.0, bottom + h / 2), (t, width + 2 * t, h)))
    return out


def make_queries(kin, scene, n: int, seed: int) -> list[np.ndarray]:
    """``n`` collision-free goal configurations for grasps inside the shelf compartments."""
    rng = np.random.default_rng(seed)
    goals: list[np.ndarray] = []
    tries = 0
    while len(goals) < n:
        tries += 1
        if tries > 50 * n:
            raise RuntimeError("could not generate enough reachable shelf targets")
        comp = rng.integers(0, 2)
        z = (0.06, 0.26)[comp] + rng.uniform(-0.02, 0.02)
        T = np.eye(4)
        T[:3, 3] = (rng.uniform(0.36, 0.45), rng.uniform(-0.12, 0.12), z)
        q = kin.ik(T, HOME, seed=int(rng.integers(0, 1 << 30)), attempts=10, is_valid=scene.is_valid)
        if q is not None:
            goals.append(q)
    return goals


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--queries", type=int, default=50)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--algorithm", default="rrtconnect", choices=("rrtconnect", "rrtstar"))
    ap.add_argument("-v", "--verbose", action="store_true")
    args = ap.parse_args(argv)

    kin = wx250s()
    with PlanningScene(ArmModel.from_sim_model("locobot_wx250s")) as scene:
        scene.set_static_boxes(shelf_boxes())
        if not scene.is_valid(HOME):
            print(f"home pose in collision: {scene.collisions(HOME)}", file=sys.stderr)
            return 2
        goals = make_queries(kin, scene, args.queries, args.seed)
        planner = ArmPlanner(scene, kin, PlannerConfig(algorithm=args.algorithm, time_limit=1.0, attempts=3, seed=args.seed))
        times, ok, direct = [], 0, 0
        checks0 = scene.checks
        for i, q in enumerate(goals):
            r = planner.plan(HOME, q)
            times.append(r.planning_time * 1e3)
            ok += r.success
            direct += r.success and r.attempts == 0
            if args.verbose:
                print(f"query {i:2d}: {'ok ' if r.success else 'FAIL'} {r.planning_time * 1e3:7.1f} ms "
                      f"{len(r.path)} waypoints {r.trajectory.duration if r.trajectory else 0:.2f} s {r.reason}")
        checks = scene.checks - checks0
    print(f"machine: {platform.machine()} {platform.processor() or ''} python {platform.python_version()}")
    print(f"scene: wx250s (locobot) + shelf of {len(shelf_boxes())} boxes; algorithm {args.algorithm}; "
          f"{args.queries} queries, seed {args.seed}")
    print(f"success: {ok}/{len(goals)} ({100.0 * ok / len(goals):.1f} %), straight-line (no OMPL) {direct}")
    print(f"planning time ms: median {statistics.median(times):.1f}, mean {statistics.mean(times):.1f}, "
          f"p90 {sorted(times)[int(0.9 * len(times)) - 1]:.1f}, max {max(times):.1f}; "
          f"{checks / len(goals):.0f} collision checks per query")
    print(f"arm_plan_median_ms: {statistics.median(times):.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
