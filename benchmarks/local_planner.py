"""Local navigation (issue 12): cost per control tick of the lidar -> costmap -> circles ->
DWA -> CLF-CBF pipeline, the QP solver against a reference, and closed-loop runs.

``.venv/bin/python benchmarks/local_planner.py [--ticks N] [--seeds S] [--qp N] [--no-closed-loop]``

Method.
1. **Tick cost.** A room of 8 x 8 m (5 cm cells, walls only in the map), 8 poles the map
   does not hold scattered 0.5-1.8 m (plus the robot radius) off the robot's straight path and 2 people walking
   across the room back and forth: 10 obstacles, nearly all within the 4 m marking range
   at any time. 400-beam scans (the RPLIDAR A2 Gazebo stand-in) are cast in pure numpy
   (not timed). The robot (LoCoBot limits, then the UR5e platform's) drives the closed
   loop at 20 Hz: A* once, then :class:`LocalPlanner`; a blocked path is re-planned (not
   timed). Timed with ``time.perf_counter`` around the tick, in two parts: ``observe``
   (scan to map, costmap clearing/marking and distance field, clustering, circles,
   tracking) and the rest of ``step`` (social scale, DWA, CBF QP); the thread's CPU time
   for the tick too (``time.thread_time``: what the tick costs without the waits another
   process's turn on a loaded machine adds to the wall time). ``--seeds`` layouts,
   ``--ticks`` ticks each (a run restarts at its start when it reaches the goal).
2. **QP.** ``--qp`` random filter QPs (random heading, 0-6 circles of safety radius
   0.3-0.7 m whose edge is 0.1-2 m away, half of them moving at about 0.5 m/s, u_ref, previous command, CLF reference or none, dt 0.05 s to 1 s, alpha
   0.21 / 0.46 / 2): DAQP (the filter's solver) against quadprog (Goldfarb-Idnani, an
   independent dual active-set code): status agreement, max |z_daqp - z_quadprog| over
   the solved ones, median time per solve of each.
3. **Closed loop** (the scenario of tests/skills/navigation/test_nav_local_planner.py:
   10 x 6 m room with a wall stub, 3 poles the map lacks, a person stepping across):
   time to the goal and the smallest gaps, with the paper's alpha (0.21, 0.46 in tight
   spaces), with alpha 1.0 / 2.0, and with the filter off.

The last line is ``local_planner_ms: X``, the LoCoBot median tick [ms].
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import statistics
import time
from dataclasses import replace
from importlib import metadata
from pathlib import Path

import cv2
import numpy as np
import quadprog

from mmexec.drivers.interfaces import OccupancyGrid, Pose2D
from mmexec.skills.navigation.astar import plan_path
from mmexec.skills.navigation.cbf import (
    PAPER_ALPHA,
    PAPER_ALPHA_TIGHT,
    CbfConfig,
    QpStatus,
    build_qp,
    solve_qp,
)
from mmexec.skills.navigation.grid import inflate
from mmexec.skills.navigation.limits import LOCOBOT_KOBUKI, UR5E_PLATFORM, BaseLimits
from mmexec.skills.navigation.local_planner import LocalPlanner, LocalPlannerConfig
from mmexec.skills.navigation.obstacles import Circles
from mmexec.skills.navigation.synthetic import Walker, cast_scan, run_closed_loop, unicycle_step

DT = 0.05


def machine() -> str:
    cpu = "unknown CPU"
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.exists():
        for line in cpuinfo.read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    return (f"machine: {platform.machine()} nproc {os.cpu_count()} '{cpu}' load {os.getloadavg()[0]:.1f}; "
            f"python {platform.python_version()} numpy {np.__version__} opencv {cv2.__version__} "
            f"daqp {metadata.version('daqp')} quadprog {metadata.version('quadprog')}")


# ---------------------------------------------------------------------------- tick cost


def room(w: int, h: int) -> OccupancyGrid:
    d = np.zeros((h, w), dtype=np.int8)
    d[0, :] = d[-1, :] = d[:, 0] = d[:, -1] = 100
    return OccupancyGrid(data=d, resolution=0.05)


def tick_costs(limits: BaseLimits, seed: int, ticks: int) -> tuple[list[float], list[float], list[float], list[int]]:
    """Per tick: wall time [s] of observe and of the rest of step, the thread's CPU time [s]
    for both, and the number of tracked circles."""
    rng = np.random.default_rng(seed)
    grid = room(160, 160)
    side = rng.choice([-1.0, 1.0], 8)
    poles = np.column_stack([rng.uniform(1.5, 6.5, 8), 4.0 + side * rng.uniform(0.5 + limits.radius, 1.8, 8)])
    radii = rng.uniform(0.08, 0.25, 8)
    walkers = [(np.array([3.0, 1.0]), np.array([0.1, 0.6])), (np.array([5.5, 7.0]), np.array([-0.1, -0.5]))]
    start, goal = Pose2D(1.0, 4.0, 0.0), (7.0, 4.0)
    cfg = LocalPlannerConfig.for_base(limits, 0.05)

    def plan(g: OccupancyGrid, s: tuple[float, float]) -> list[tuple[float, float]] | None:
        p = plan_path(inflate(g, limits.radius, 0.05), s, goal)
        return None if p is None else [s, *p[1:-1], goal]

    lp = LocalPlanner(grid, cfg)
    path = plan(grid, (start.x, start.y))
    assert path is not None
    lp.set_path(path, 0.0)
    pose, v, w, t = start, 0.0, 0.0, 0.0
    obs, rest, cpu, counts = [], [], [], []
    last_replan = -1.0
    for _ in range(ticks):
        people = []
        for p0, vel in walkers:  # back and forth across the room, bouncing off y = 0.6 / 7.4
            y = p0[1] + vel[1] * t
            span = 6.8
            k = (y - 0.6) % (2 * span)
            people.append([p0[0] + vel[0] * math.sin(t / 3.0), 0.6 + (k if k < span else 2 * span - k)])
        centres = np.vstack([poles, people])
        scan = cast_scan(grid, pose, centres, np.append(radii, [0.22, 0.22]), n_beams=400, stamp=t)
        c0, t0 = time.thread_time(), time.perf_counter()
        lp.observe(scan, pose)
        t1 = time.perf_counter()
        cmd = lp.step(pose, v, w, t, DT)
        t2, c2 = time.perf_counter(), time.thread_time()
        obs.append(t1 - t0)
        rest.append(t2 - t1)
        cpu.append(c2 - c0)
        counts.append(len(cmd.circles))
        if cmd.path_blocked and t - last_replan > 1.0:
            p = plan(lp.replan_grid(t), (pose.x, pose.y))
            if p is not None:
                lp.set_path(p, t)
                last_replan = t
        v, w = cmd.v, cmd.w
        pose = unicycle_step(pose, v, w, DT)
        t += DT
        if cmd.status.value in ("goal_reached", "stuck"):  # start over (new tracker, costmap)
            lp = LocalPlanner(grid, cfg)
            lp.set_path(path, t)
            pose, v, w = start, 0.0, 0.0
    return obs, rest, cpu, counts


def pct(xs: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(xs), q))


# ---------------------------------------------------------------------------- QP


def random_qp(rng: np.random.Generator, lim: BaseLimits):  # type: ignore[no-untyped-def]
    k = int(rng.integers(0, 7))
    pose = Pose2D(0.0, 0.0, float(rng.uniform(-math.pi, math.pi)))
    safety = rng.uniform(0.3, 0.7, k)
    bearing, dist = rng.uniform(-math.pi, math.pi, k), safety + rng.uniform(0.1, 2.0, k)
    circles = Circles(np.column_stack([dist * np.cos(bearing), dist * np.sin(bearing)]), safety - 0.2, safety,
                      rng.normal(0.0, 0.5, (k, 2)) * (rng.random((k, 1)) < 0.5), np.arange(k), np.zeros(k, bool))
    ref = Pose2D(*rng.normal(0.0, 0.5, 2), float(rng.uniform(-math.pi, math.pi))) if rng.random() < 0.8 else None
    cfg = CbfConfig(limits=lim, alpha=float(rng.choice([0.21, 0.46, 2.0])))
    u_ref = (float(rng.uniform(lim.min_v, lim.max_v)), float(rng.uniform(-lim.max_w, lim.max_w)))
    u_prev = (float(rng.uniform(lim.min_v, lim.max_v)), float(rng.uniform(-lim.max_w, lim.max_w)))
    return build_qp(pose, u_ref, ref, circles, u_prev, float(rng.choice([0.05, 0.25, 1.0])), cfg)


def qp_check(n: int) -> tuple[int, int, int, float, float, float]:
    """(instances, solved, disagreements, max |dz|, DAQP median us, quadprog median us)."""
    rng = np.random.default_rng(2024)
    lim = replace(LOCOBOT_KOBUKI, min_v=-0.2)
    solved = disagree = 0
    worst = 0.0
    t_daqp, t_qp = [], []
    for _ in range(n):
        qp = random_qp(rng, lim)
        keep = qp.upper < 1e29  # quadprog: C^T x >= b, every bound as a row
        n_z = qp.H.shape[0]  # (v, w, mu, s)
        C = np.vstack([-qp.A, np.eye(n_z), -np.eye(n_z)[keep]]).T
        b = np.concatenate([-qp.b, qp.lower, -qp.upper[keep]])
        t0 = time.perf_counter()
        z, status, _ = solve_qp(qp)
        t1 = time.perf_counter()
        try:
            ref = quadprog.solve_qp(qp.H, -qp.f, C, b)[0]
        except ValueError:
            ref = None
        t2 = time.perf_counter()
        t_daqp.append(t1 - t0)
        t_qp.append(t2 - t1)
        if (ref is None) != (status is QpStatus.INFEASIBLE):
            disagree += 1
        elif ref is not None:
            solved += 1
            worst = max(worst, float(np.max(np.abs(z - ref))))
    return n, solved, disagree, worst, statistics.median(t_daqp) * 1e6, statistics.median(t_qp) * 1e6


# ---------------------------------------------------------------------------- closed loop


def closed_loop_rows() -> list[str]:
    d = np.zeros((120, 200), dtype=np.int8)
    d[0, :] = d[-1, :] = d[:, 0] = d[:, -1] = 100
    d[0:50, 95:105] = 100
    grid = OccupancyGrid(data=d, resolution=0.05)
    poles, radii = np.array([[3.0, 3.35], [6.5, 4.0], [7.5, 2.9]]), np.array([0.12, 0.2, 0.15])
    walker = Walker(start=(5.5, 5.2), velocity=(0.0, -0.5), radius=0.22, trigger_x=4.0)
    rows = []
    default = CbfConfig()
    for label, alpha, tight, use in (("paper alpha 0.21 / 0.46", PAPER_ALPHA, PAPER_ALPHA_TIGHT, True),
                                     (f"alpha {default.alpha:g} / {default.alpha_tight:g} (default)", default.alpha,
                                      default.alpha_tight, True),
                                     ("filter off (DWA alone)", default.alpha, default.alpha_tight, False)):
        cfg = LocalPlannerConfig.for_base(LOCOBOT_KOBUKI, 0.05, cbf=CbfConfig(alpha=alpha, alpha_tight=tight),
                                          use_cbf=use)
        r = run_closed_loop(grid, Pose2D(1.0, 3.0, 0.0), (9.0, 3.0), poles, radii, walker, cfg, t_max=120.0)
        rows.append(f"  {label:<24} reached {r.reached!s:<5} in {r.time:5.1f} s; smallest gap pole "
                    f"{r.min_pole_gap:+.3f} m, person {r.min_person_gap:+.3f} m (margin 0.05); re-plans "
                    f"{r.replans}; ticks {r.ticks}: command changed {r.filtered}, a barrier binding {r.barrier_active}, "
                    f"barriers not all kept (escape or brake) {r.infeasible}")
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--ticks", type=int, default=1500, help="ticks per layout (default 1500 = 75 s at 20 Hz)")
    ap.add_argument("--seeds", type=int, default=3, help="random layouts per base (default 3)")
    ap.add_argument("--qp", type=int, default=10000, help="random QP instances (default 10000)")
    ap.add_argument("--no-closed-loop", action="store_true", help="skip the closed-loop runs")
    args = ap.parse_args(argv)
    print(machine())
    headline = math.nan
    for name, lim in (("LoCoBot (Kobuki)", LOCOBOT_KOBUKI), ("UR5e platform", UR5E_PLATFORM)):
        obs: list[float] = []
        rest: list[float] = []
        cpu: list[float] = []
        counts: list[int] = []
        for seed in range(args.seeds):
            o, r, c, k = tick_costs(lim, seed, args.ticks)
            obs += o
            rest += r
            cpu += c
            counts += k
        tick = [a + b for a, b in zip(obs, rest, strict=True)]
        print(f"{name}: {len(tick)} ticks, 400 beams, 10 obstacles (8 poles, 2 people; tracked circles per "
              f"tick: median {statistics.median(counts):.0f}, max {max(counts)})")
        print(f"  tick (observe + DWA + CBF): median {pct(tick, 50) * 1e3:.2f} ms, p99 {pct(tick, 99) * 1e3:.2f} ms, "
              f"max {max(tick) * 1e3:.2f} ms = {pct(tick, 50) / DT * 100:.1f} % of a core at 20 Hz; thread CPU "
              f"time: median {pct(cpu, 50) * 1e3:.2f} ms, p99 {pct(cpu, 99) * 1e3:.2f} ms")
        print(f"  observe (scan, costmap, clusters, tracks): median {pct(obs, 50) * 1e3:.2f} ms, "
              f"p99 {pct(obs, 99) * 1e3:.2f} ms; DWA + CBF: median {pct(rest, 50) * 1e3:.2f} ms, "
              f"p99 {pct(rest, 99) * 1e3:.2f} ms")
        if lim is LOCOBOT_KOBUKI:
            headline = pct(tick, 50) * 1e3
    n, solved, disagree, worst, us_daqp, us_qp = qp_check(args.qp)
    print(f"QP: {n} random instances, {solved} solved, {n - solved - disagree} infeasible by both, "
          f"{disagree} status disagreements; max |z_daqp - z_quadprog| {worst:.2e}; median solve "
          f"DAQP {us_daqp:.1f} us (solve_qp: bounds stacked, DAQP set-up and solve), quadprog {us_qp:.1f} us")
    if not args.no_closed_loop:
        print("closed loop (LoCoBot, test scenario: 8 m through 3 unknown poles and a person crossing):")
        for row in closed_loop_rows():
            print(row)
    print(f"local_planner_ms: {headline:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
