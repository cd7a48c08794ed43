"""Simulation speed: physics step cost, camera frame cost, lidar scan cost, and the
real-time factor of the base driving a 10 m path while the camera renders at the rate
perception uses.

The simulation settings are the ``sim:`` section of a mission config (default
``config/locobot_sim.yaml``, the fetch mission's: its physics rate and camera resolution);
``--camera WxH`` and ``--physics-hz`` override them. Run:
``.venv/bin/python benchmarks/sim_speed.py [--config FILE] [--camera WxH] [--rate HZ]``.
The last line is ``sim_realtime_factor: X``. Times are wall-clock (``perf_counter``) and
process CPU (``process_time``, less disturbed by other jobs on a shared machine). The lidar
line times a scan both ways in the same run: pybullet's ``rayTestBatch`` and the closed
form of :mod:`mmexec.sim.raycast` (``sim.lidar.raycast``)."""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import pybullet as p

from mmexec.config.yamlload import InputError, YDict, load_yaml, load_yaml_text
from mmexec.drivers.geometry import wrap_angle
from mmexec.drivers.interfaces import Pose2D
from mmexec.sim.backend import SimRobot, build
from mmexec.sim.capabilities import SimLidar

ROOT = Path(__file__).resolve().parent.parent


def _section(args: argparse.Namespace) -> Any:
    """The config's ``sim:`` section with the command-line overrides applied."""
    cfg = load_yaml(args.config)
    sim = dict(cfg.get("sim") or {}) if isinstance(cfg, dict) else {}
    if args.camera:
        w, h = (int(x) for x in args.camera.split("x"))
        cam = dict(sim.get("camera") or {})
        cam.update(width=w, height=h)
        sim["camera"] = cam
    if args.physics_hz:
        sim["physics_hz"] = args.physics_hz
    # re-load through the safe loader so the backend gets a located section
    out = load_yaml_text(json.dumps(sim), f"{args.config} (sim, with overrides)")
    assert isinstance(out, YDict)
    return out


def _median_ms(fn: Any, n: int) -> tuple[float, float]:
    wall, cpu = [], []
    for _ in range(n):
        t, c = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c)
    return 1e3 * statistics.median(wall), 1e3 * statistics.median(cpu)


def drive(r: SimRobot, rate: float, period: float = 0.1) -> tuple[float, float, float, float, int]:
    """Drive a 10 m loop of straight legs in the free middle of the lab at 0.5 m/s,
    rendering a frame every ``1/rate`` s of sim time. Returns (metres, sim s, wall s,
    cpu s, frames)."""
    r.core.place_base(Pose2D(1.3, 1.5, 0.0))
    r.base.reset_estimate(Pose2D(1.3, 1.5, 0.0))
    frame_every = max(1, round(1.0 / (rate * period)))
    f0 = r.camera.frames
    t0_sim, t0, c0 = r.clock.now(), time.perf_counter(), time.process_time()
    travelled, last, k = 0.0, r.truth.base_pose(), 0
    legs = [(1.3, 1.5), (2.2, 1.9), (1.3, 2.4), (2.2, 1.9)]
    leg = 1
    while travelled < 10.0:
        gx, gy = legs[leg % len(legs)]
        pose = r.truth.base_pose()
        if math.hypot(gx - pose.x, gy - pose.y) < 0.1:
            leg += 1
            continue
        err = wrap_angle(math.atan2(gy - pose.y, gx - pose.x) - pose.theta)
        r.base.set_velocity(0.5 if abs(err) < 0.5 else 0.0, max(-2.0, min(2.0, 3.0 * err)))
        r.spin(period)
        if k % frame_every == 0:
            r.camera.frame()
        k += 1
        now = r.truth.base_pose()
        travelled += now.distance_to(last)
        last = now
    return (travelled, r.clock.now() - t0_sim, time.perf_counter() - t0, time.process_time() - c0,
            r.camera.frames - f0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", default=str(ROOT / "config" / "locobot_sim.yaml"),
                    help="mission config whose sim: section is measured (default: the fetch mission's)")
    ap.add_argument("--camera", help="override the camera resolution WxH")
    ap.add_argument("--rate", type=float, default=2.0, help="perception frame rate while driving [Hz] (default 2)")
    ap.add_argument("--physics-hz", type=int, help="override sim.physics_hz")
    args = ap.parse_args()
    try:
        sec = _section(args)
        r = build(sec, profile={}, seed=0, options={})
    except InputError as e:
        print(f"sim_speed: {e}", file=sys.stderr)
        raise SystemExit(2) from None
    try:
        hz = r.clock.hz
        w, h = r.camera.intrinsics.width, r.camera.intrinsics.height
        r.spin(3.0)  # items settle and fall asleep
        n = 2 * hz
        wall, cpu = _median_ms(lambda: [p.stepSimulation(physicsClientId=r.cid) for _ in range(n)], 3)
        print(f"physics_step_us: {1e3 * cpu / n:.0f} cpu, {1e3 * wall / n:.0f} wall "
              f"(one stepSimulation, {hz} Hz, robot idle, items asleep)")
        steps = r.physics_steps
        wall, cpu = _median_ms(lambda: r.spin(1.0), 3)
        print(f"spin_at_rest_ms_per_sim_s: {cpu:.2f} cpu, {wall:.2f} wall "
              f"({r.physics_steps - steps} physics steps run: physics pauses at rest)")
        wall, cpu = _median_ms(r.camera.frame, 5)
        print(f"camera_frame_ms: {cpu:.1f} cpu, {wall:.1f} wall ({w}x{h}, RGB + depth, TinyRenderer, shadows off)")
        lidar = r.lidar

        def fresh_scan() -> None:
            lidar._last = None  # a new cast each time (a scan in the same substep reuses its rays)
            lidar.scan()

        wall, cpu = _median_ms(fresh_scan, 20)
        closed = SimLidar(r.core, lidar.beams, lidar.range_min, lidar.range_max, lidar.noise,
                          reflectors=frozenset(x.name for x in r.world.spec.reflectors), raycast="closed_form")
        real, lidar = lidar, closed
        cwall, ccpu = _median_ms(fresh_scan, 20)
        lidar = real
        print(f"lidar_scan_ms: {cpu:.2f} cpu, {wall:.2f} wall ({r.lidar.beams} beams, raycast pybullet); "
              f"{ccpu:.2f} cpu, {cwall:.2f} wall (raycast closed_form): {cpu / ccpu:.1f}x")
        checks, bumps = r.base.exact_checks, r.base.bumps
        metres, sim_s, wall_s, cpu_s, frames = drive(r, args.rate)
        print(f"drive: {metres:.1f} m in {sim_s:.1f} s sim, {wall_s:.2f} s wall, {cpu_s:.2f} s cpu, {frames} frames "
              f"at {args.rate:g} Hz ({w}x{h}), {hz} Hz physics, {r.base.exact_checks - checks} exact bumper tests, "
              f"{r.base.bumps - bumps} bumper stops")
        print(f"sim_realtime_factor_cpu: {sim_s / cpu_s:.1f}")
        print(f"sim_realtime_factor: {sim_s / wall_s:.1f}")
    finally:
        r.close()


if __name__ == "__main__":
    main()
