"""Localisation accuracy of the sim LoCoBot: odometry alone, plain AMCL and
reflector-enhanced AMCL (reflector-amcl-tracking-grasp 4.3.1; issue 11).

``.venv/bin/python benchmarks/localization.py [--world NAME_OR_PATH] [--runs N] [--seed S]
[--goals G] [--beams B] [--range-noise F]``

Method. The world's map and reflectors are written by ``mmexec.drivers.maps.write_map`` (as
``python -m mmexec.sim.mapgen`` does) and read back as a robot would (``load_map``,
``load_reflectors``). Each run builds the sim LoCoBot with the ``realistic`` odometry
profile and the RPLIDAR A2 lidar model (``beams`` per scan,
range noise ``F`` of the range, quality values), puts it at a random free pose and drives
``G`` random free goals: A* on the map inflated by the footprint, a path tracker on the
TRUE pose (the estimators are measured, never used for control), a scan every 0.1 s of
sim time (10 Hz). The three estimators see the same scans and odometry: the odometry pose
itself, and two particle filters (plain: ``AmclConfig(reflectors=None)``; enhanced: the
defaults, with the map's reflectors), both started from the start pose with a 10 cm /
0.1 rad error and their default spread. At each goal, once the base has stopped, each
estimate (a filter's ``T_map_odom`` times the current odometry, as ROS publishes it) is
compared with the truth: position error [m] and heading error [rad].

Fault runs (same count, other seeds): ``kidnap`` at a random time between 15 and 25 s
(to a random clear pose): the recovery time is the sim time from the kidnap until the
estimate stays within 5 cm and 0.05 rad for good (to 30 s after it), for the two filters
and for plain AMCL with ROS's suggested random-particle recovery (``recovery_alpha_slow``
0.001, ``recovery_alpha_fast`` 0.1; off by default); ``reflector_dropout``
of every reflector for 20 s from a random time between 15 and 25 s: the mean error per
scan during the dropout and in the 20 s after it.

Update time: wall and process CPU time of each ``ParticleFilter.update`` that ran
(motion above the filter's thresholds; while driving, nearly every scan), with the
particle count at that update. On a shared machine the CPU time is the steadier figure. The last
line is ``loc_mean_error_cm: X``, the enhanced filter's mean position error at the goals.
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from mmexec.drivers.geometry import wrap_angle as wrap
from mmexec.drivers.interfaces import LaserScan, Pose2D
from mmexec.drivers.maps import load_map, write_map
from mmexec.sim.backend import SimRobot, build
from mmexec.sim.world import load_world
from mmexec.skills.localization import AmclConfig, ParticleFilter, ReflectorMap, load_reflectors
from mmexec.skills.navigation.astar import plan_path, simplify_path
from mmexec.skills.navigation.grid import CostMap, inflate
from mmexec.skills.navigation.tracker import PathTracker, TrackerConfig

#: control period and scan period [s] of sim time; physics rate [Hz]
CONTROL_DT, SCAN_EVERY, PHYSICS_HZ = 0.05, 2, 60
#: how close a kidnapped estimate must come back, and stay: position [m], heading [rad]
RECOVERED = (0.05, 0.05)
ESTIMATORS = ("odometry", "amcl", "reflector amcl")
FILTERS = ESTIMATORS[1:]
#: the kidnap runs also measure plain AMCL with ROS's suggested random-particle recovery
#: (off by default, as in ROS; see skills/localization/amcl.py)
RECOVERY = "amcl, recovery on"


@dataclass
class Filters:
    """The particle filters fed side by side (name -> filter), and their update times [s]
    and particle counts."""

    filters: dict[str, ParticleFilter]
    times: dict[str, list[float]] = field(default_factory=dict)
    cpu: dict[str, list[float]] = field(default_factory=dict)  #: process CPU time [s] of the same updates
    particles: dict[str, list[int]] = field(default_factory=dict)
    fixes: int = 0  #: updates of the enhanced filter with a reflector fix (three or more matched)

    def feed(self, odom: Pose2D, scan: LaserScan) -> None:
        o = np.array([odom.x, odom.y, odom.theta])
        for name, pf in self.filters.items():
            t, c = time.perf_counter(), time.process_time()
            ran = pf.update(o, scan.ranges, scan.angles, scan.range_max, scan.intensities)
            if ran:
                self.times.setdefault(name, []).append(time.perf_counter() - t)
                self.cpu.setdefault(name, []).append(time.process_time() - c)
                self.particles.setdefault(name, []).append(len(pf.particles))
                self.fixes += name == "reflector amcl" and pf.last_fix is not None

    def poses(self, odom: Pose2D) -> dict[str, np.ndarray]:
        """Each estimator's pose ``(x, y, theta)`` in ``map`` now."""
        out = {"odometry": np.array([odom.x, odom.y, odom.theta])}
        for name, pf in self.filters.items():
            m = pf.map_to_odom()
            x, y, _ = m @ np.array([odom.x, odom.y, 1.0])
            out[name] = np.array([x, y, math.atan2(m[1, 0], m[0, 0]) + odom.theta])
        return out


#: an estimate's error: position [m], |heading| [rad], |x| [m], |y| [m]
Error = tuple[float, float, float, float]


def errors(poses: dict[str, np.ndarray], truth: Pose2D) -> dict[str, Error]:
    """Each estimate's error against the truth."""
    return {k: (math.hypot(p[0] - truth.x, p[1] - truth.y), abs(float(wrap(p[2] - truth.theta))),
                abs(p[0] - truth.x), abs(p[1] - truth.y)) for k, p in poses.items()}


class Run:
    """One sim robot driving random goals with the filters fed on the way."""

    def __init__(self, world: str, seed: int, maps: tuple[Any, ReflectorMap], *, beams: int, range_noise: float,
                 faults: dict[str, Any] | None = None, recovery: bool = False) -> None:
        section = {
            "robot": "locobot_wx250s", "world": world, "physics_hz": PHYSICS_HZ,
            "lidar": {"beams": beams, "noise": 0.002, "noise_fraction": range_noise, "quality": "rplidar_a2"},
            "odometry_noise": {"profile": "realistic"},
            "faults": faults or {},
        }
        self.robot: SimRobot = build(section, profile={}, seed=seed, options={})  # type: ignore[arg-type]
        self.rng = np.random.default_rng(seed)
        grid, refl = maps
        self.costmap: CostMap = inflate(grid, self.robot.base.radius, 0.05)
        start = self._free_pose(min_from=None)
        self.robot.core.place_base(start)
        self.robot.base.reset_estimate(start)
        scan = self.robot.lidar.scan()
        assert scan is not None
        T = scan.T_base_lidar
        mount = (float(T[0, 3]), float(T[1, 3]), math.atan2(T[1, 0], T[0, 0]))
        configs = {"amcl": AmclConfig(reflectors=None), "reflector amcl": AmclConfig(reflectors=refl.config())}
        if recovery:
            configs[RECOVERY] = AmclConfig(reflectors=None, recovery_alpha_slow=0.001, recovery_alpha_fast=0.1)
        guess = (start.x + self.rng.normal(0, 0.1), start.y + self.rng.normal(0, 0.1), start.theta + self.rng.normal(0, 0.1))
        filters = {}
        for k, (name, cfg) in enumerate(configs.items()):
            filters[name] = ParticleFilter(grid, cfg, reflectors=refl.positions, mount=mount,
                                           rng=np.random.default_rng(seed + 1 + k))
            filters[name].initialise(guess)
        self.filters = Filters(filters)
        self.ticks = 0
        self.trace: list[tuple[float, dict[str, Error]]] = []  #: (sim time, errors) per scan

    def _free_pose(self, min_from: Pose2D | None) -> Pose2D:
        sx, sy = self.robot.world.spec.room.size
        for _ in range(10000):
            x, y = float(self.rng.uniform(0, sx)), float(self.rng.uniform(0, sy))
            if self.costmap.is_free(x, y) and (min_from is None or math.hypot(x - min_from.x, y - min_from.y) > 1.0):
                return Pose2D(x, y, float(self.rng.uniform(-math.pi, math.pi)))
        raise RuntimeError("no free pose in the map")

    def tick(self, v: float, w: float) -> None:
        """One control period: command, step the sim, feed a scan every SCAN_EVERY ticks."""
        r = self.robot
        r.base.set_velocity(v, w)
        r.spin(CONTROL_DT)
        self.ticks += 1
        if self.ticks % SCAN_EVERY == 0:
            scan = r.lidar.scan()
            if scan is not None:
                odom = r.base.state().pose
                self.filters.feed(odom, scan)
                self.trace.append((r.clock.now(), errors(self.filters.poses(odom), r.truth.base_pose())))

    def goto(self, goal: Pose2D, timeout: float = 90.0, stop: Callable[[], bool] | None = None) -> bool:
        """Drive to ``goal`` on the true pose; False when no path or not reached in time."""
        r = self.robot
        here = r.truth.base_pose()
        path = plan_path(self.costmap, (here.x, here.y), (goal.x, goal.y))
        if path is None:  # (put down by a kidnap where the planner cannot start): wait 0.5 s
            for _ in range(10):
                self.tick(0.0, 0.0)
            return False
        tracker = PathTracker(simplify_path(self.costmap, path), TrackerConfig(max_v=0.5, max_w=1.5), goal.theta)
        t_end = r.clock.now() + timeout
        kidnaps = len(r.truth.faults_fired())
        while r.clock.now() < t_end:
            if stop is not None and stop():
                return False
            st = r.base.state()
            v, w, done = tracker.step(r.truth.base_pose(), st.v, st.w, CONTROL_DT)
            if done:
                for _ in range(10):  # 0.5 s standing still
                    self.tick(0.0, 0.0)
                return True
            self.tick(v, w)
            fired = r.truth.faults_fired()
            if len(fired) > kidnaps and any(f.startswith("kidnap") for _, f in fired[kidnaps:]):
                return self.goto(goal, max(1.0, t_end - r.clock.now()), stop)  # re-plan from where it was put
            kidnaps = len(fired)
        return False

    def next_goal(self) -> Pose2D:
        return self._free_pose(min_from=self.robot.truth.base_pose())

    def close(self) -> None:
        self.robot.close()


def route(world: str, seed: int, maps: tuple[Any, ReflectorMap], goals: int, **kw: Any
          ) -> tuple[list[dict[str, Error]], Filters, int]:
    """Errors at each goal reached, the filters (for their update times), goals missed."""
    run = Run(world, seed, maps, **kw)
    out, missed = [], 0
    try:
        for _ in range(goals):
            if run.goto(run.next_goal()):
                r = run.robot
                out.append(errors(run.filters.poses(r.base.state().pose), r.truth.base_pose()))
            else:
                missed += 1
        return out, run.filters, missed
    finally:
        run.close()


def drive_until(run: Run, t_end: float) -> None:
    """Drive random goals until sim time ``t_end`` [s]."""
    clock = run.robot.clock
    while clock.now() < t_end:
        run.goto(run.next_goal(), stop=lambda: clock.now() >= t_end)


def kidnap_run(world: str, seed: int, maps: tuple[Any, ReflectorMap], **kw: Any) -> dict[str, float]:
    """Recovery time [s] of each filter after a kidnap: from the kidnap to the last scan
    whose error was above :data:`RECOVERED` (inf: still above within 3 s of the run's end,
    30 s after the kidnap)."""
    t_k = float(np.random.default_rng(seed).uniform(15.0, 25.0))
    run = Run(world, seed, maps, faults={"kidnap": {"at": t_k}}, recovery=True, **kw)
    try:
        drive_until(run, t_k + 30.0)
    finally:
        run.close()
    out = {}
    for name in (*FILTERS, RECOVERY):
        after = [(t, e[name]) for t, e in run.trace if t >= t_k]
        bad = [t for t, (d, h, *_) in after if d > RECOVERED[0] or h > RECOVERED[1]]
        if not bad:
            out[name] = 0.0
        elif bad[-1] > after[-1][0] - 3.0:
            out[name] = math.inf
        else:
            out[name] = bad[-1] + 0.1 - t_k  # recovered at the next scan
    return out


def dropout_run(world: str, seed: int, maps: tuple[Any, ReflectorMap], **kw: Any) -> dict[str, tuple[float, float]]:
    """Mean position error [m] of each estimator over the scans during a 20 s dropout of
    every reflector, and over those of the 20 s after it."""
    t0 = float(np.random.default_rng(seed).uniform(15.0, 25.0))
    run = Run(world, seed, maps, faults={"reflector_dropout": {"intervals": [[t0, t0 + 20.0]]}}, **kw)
    try:
        drive_until(run, t0 + 40.0)
    finally:
        run.close()

    def mean(name: str, lo: float, hi: float) -> float:
        return float(np.mean([e[name][0] for t, e in run.trace if lo <= t < hi]))

    return {name: (mean(name, t0, t0 + 20.0), mean(name, t0 + 20.0, t0 + 40.0)) for name in ESTIMATORS}


def _stats(xs: list[float]) -> tuple[float, float, float]:
    """Mean, median, 95th percentile."""
    a = np.asarray(xs)
    return float(a.mean()), float(np.median(a)), float(np.percentile(a, 95))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("--world", default="lab", help="shipped world name or world .yaml (default lab)")
    ap.add_argument("--runs", type=int, default=6, help="route runs, and as many kidnap and dropout runs (default 6)")
    ap.add_argument("--seed", type=int, default=1, help="first route run's seed (default 1)")
    ap.add_argument("--goals", type=int, default=8, help="goals per route run (default 8)")
    ap.add_argument("--beams", type=int, default=400, help="lidar beams per scan (default 400: 0.9 deg)")
    ap.add_argument("--range-noise", type=float, default=0.0075,
                    help="range noise std as a fraction of the range (default 0.0075), plus 2 mm")
    args = ap.parse_args(argv)
    kw = {"beams": args.beams, "range_noise": args.range_noise}
    world = load_world(args.world, randomize=False)
    with tempfile.TemporaryDirectory() as tmp:
        yaml_path, _ = write_map(world.occupancy(0.05), Path(tmp) / "map.yaml", reflectors=world.spec.reflectors)
        maps = (load_map(yaml_path), load_reflectors(yaml_path))
    print(f"world {world.name}: {len(maps[1])} reflectors (radius {maps[1].radius} m); {args.runs} route runs x "
          f"{args.goals} goals, seeds {args.seed}..{args.seed + args.runs - 1}; lidar {args.beams} beams, range noise "
          f"{100 * args.range_noise:g} % + 2 mm, rplidar_a2 quality; odometry 'realistic'")
    at_goals: list[dict[str, Error]] = []
    times: dict[str, list[float]] = {n: [] for n in FILTERS}
    cpu: dict[str, list[float]] = {n: [] for n in FILTERS}
    counts: dict[str, list[int]] = {n: [] for n in FILTERS}
    missed = fixes = 0
    wall = time.perf_counter()
    for i in range(args.runs):
        out, filters, miss = route(args.world, args.seed + i, maps, args.goals, **kw)
        at_goals += out
        missed += miss
        fixes += filters.fixes
        for n in FILTERS:
            times[n] += filters.times[n]
            cpu[n] += filters.cpu[n]
            counts[n] += filters.particles[n]
    updates = len(times["reflector amcl"])
    print(f"\n{len(at_goals)} goals reached ({missed} not), {time.perf_counter() - wall:.0f} s wall; the enhanced "
          f"filter had a reflector fix at {fixes} of its {updates} updates ({100 * fixes / max(1, updates):.0f} %)")
    print("error at the goals: position [cm] (|x|, |y| means), heading [rad]")
    print(f"{'estimator':<16}{'x':>6}{'y':>6}{'mean':>7}{'median':>8}{'p95':>7}{'<12 mm':>8}{'heading':>9}{'p95':>8}")
    for name in ESTIMATORS:
        d = [100 * e[name][0] for e in at_goals]
        m, med, p95 = _stats(d)
        hm, _, hp95 = _stats([e[name][1] for e in at_goals])
        x, y = (float(np.mean([100 * e[name][k] for e in at_goals])) for k in (2, 3))
        share = float(np.mean(np.asarray(d) < 1.2))
        print(f"{name:<16}{x:>6.2f}{y:>6.2f}{m:>7.2f}{med:>8.2f}{p95:>7.2f}{share:>8.2f}{hm:>9.4f}{hp95:>8.4f}")
    print()
    for n in FILTERS:
        print(f"update time {n}: median {1e3 * statistics.median(times[n]):.2f} ms wall "
              f"({1e3 * statistics.median(cpu[n]):.2f} ms CPU), p95 {1e3 * float(np.percentile(times[n], 95)):.2f} ms "
              f"wall over {len(times[n])} updates "
              f"({args.beams} beams; particles median {statistics.median(counts[n]):.0f}, max {max(counts[n])})")
    rec: dict[str, list[float]] = {n: [] for n in (*FILTERS, RECOVERY)}
    drop: dict[str, list[tuple[float, float]]] = {n: [] for n in ESTIMATORS}
    for i in range(args.runs):
        for n, t in kidnap_run(args.world, 1000 + args.seed + i, maps, **kw).items():
            rec[n].append(t)
        for n, dd in dropout_run(args.world, 2000 + args.seed + i, maps, **kw).items():
            drop[n].append(dd)
    print()
    for n, ts in rec.items():
        ok = sorted(t for t in ts if math.isfinite(t))
        spread = f", median {statistics.median(ok):.1f} s, max {ok[-1]:.1f} s" if ok else ""
        print(f"kidnap recovery {n}: {len(ok)}/{len(ts)} runs back within {100 * RECOVERED[0]:g} cm and "
              f"{RECOVERED[1]:g} rad for good{spread}")
    for n in ESTIMATORS:
        during, after = (float(np.mean([100 * dd[k] for dd in drop[n]])) for k in (0, 1))
        print(f"reflector dropout {n}: mean error {during:.2f} cm during the 20 s, {after:.2f} cm in the 20 s after")
    m = float(np.mean([100 * e["reflector amcl"][0] for e in at_goals]))
    print(f"loc_mean_error_cm: {m:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
