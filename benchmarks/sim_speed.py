"""Simulation speed: physics steps/s, camera frame cost, lidar scan cost, and the
real-time factor of the base driving a 10 m path while the camera renders at the rate
perception uses. Run: ``.venv/bin/python benchmarks/sim_speed.py [--camera WxH] [--rate HZ]``.
The last line is ``sim_realtime_factor: X``."""

from __future__ import annotations

import argparse
import math
import statistics
import time

from mmexec.config.yamlload import load_yaml_text
from mmexec.drivers.interfaces import Pose2D
from mmexec.sim.backend import build


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--camera", default="640x480", help="camera resolution WxH (default 640x480)")
    ap.add_argument("--rate", type=float, default=2.0, help="perception frame rate while driving [Hz]")
    ap.add_argument("--physics-hz", type=int, default=240)
    args = ap.parse_args()
    w, h = (int(x) for x in args.camera.split("x"))
    sec = load_yaml_text(f"world: lab\nphysics_hz: {args.physics_hz}\ncamera: {{width: {w}, height: {h}}}\n", "bench")
    r = build(sec, profile={}, seed=0, options={})
    try:
        r.spin(1.0)
        n = 2 * args.physics_hz
        t = time.perf_counter()
        r.spin(2.0)
        steps = n / (time.perf_counter() - t)
        print(f"physics_steps_per_s: {steps:.0f} (robot idle, items resting, {args.physics_hz} Hz)")
        costs = []
        for _ in range(5):
            t = time.perf_counter()
            r.camera.frame()
            costs.append(time.perf_counter() - t)
        print(f"camera_frame_ms: {1e3 * statistics.median(costs):.1f} ({w}x{h}, RGB + depth, TinyRenderer, shadows off)")
        costs = []
        for _ in range(20):
            t = time.perf_counter()
            r.lidar.scan()
            costs.append(time.perf_counter() - t)
        print(f"lidar_scan_ms: {1e3 * statistics.median(costs):.2f} ({r.lidar.beams} beams)")
        # 10 m path: a loop of straight legs in the free middle of the lab at 0.5 m/s
        r.core.place_base(Pose2D(1.3, 1.5, 0.0))
        r.base.reset_estimate(Pose2D(1.3, 1.5, 0.0))
        period, frame_every = 0.1, max(1, round(1.0 / (args.rate * 0.1)))
        t0_sim, t0 = r.clock.now(), time.perf_counter()
        travelled, last, k = 0.0, r.truth.base_pose(), 0
        legs = [(1.3, 1.5), (2.2, 1.9), (1.3, 2.4), (2.2, 1.9)]
        leg = 1
        while travelled < 10.0:
            gx, gy = legs[leg % len(legs)]
            pose = r.truth.base_pose()
            if math.hypot(gx - pose.x, gy - pose.y) < 0.1:
                leg += 1
                continue
            err = math.atan2(gy - pose.y, gx - pose.x) - pose.theta
            err = (err + math.pi) % (2 * math.pi) - math.pi
            r.base.set_velocity(0.5 if abs(err) < 0.5 else 0.0, max(-2.0, min(2.0, 3.0 * err)))
            r.spin(period)
            if k % frame_every == 0:
                r.camera.frame()
            k += 1
            now = r.truth.base_pose()
            travelled += now.distance_to(last)
            last = now
        sim_s, wall_s = r.clock.now() - t0_sim, time.perf_counter() - t0
        print(f"drive: {travelled:.1f} m in {sim_s:.1f} s sim, {wall_s:.2f} s wall, {r.camera.frames - 5} frames "
              f"at {args.rate} Hz, {r.base.bumps} bumper stops")
        print(f"sim_realtime_factor: {sim_s / wall_s:.1f}")
    finally:
        r.close()


if __name__ == "__main__":
    main()
