"""Marker detection + pose benchmark on synthetic 640x480 frames.

A sequence of frames of one 0.10 m DICT_4X4_50 marker on a textured wall, seen from
0.6-1.8 m while the camera drifts (as during an approach), with pixel noise. Per frame
the timed work is what a skill does: detect marker 7 (ROI around the last detection when
it holds the wanted id, else a 2x downscaled whole-image pass, else full resolution),
refine the corners at full resolution, solvePnP IPPE_SQUARE, depth refinement. The same
frames without wanted ids (the whole image searched every frame) are timed too. OpenCV's default detector on the same frames is timed
for comparison. Prints accuracy against ground truth and LAST ``marker_pose_ms: X``
(median per frame).

    .venv/bin/python benchmarks/perception.py [--frames 100] [--seed 0]
"""

from __future__ import annotations

import argparse
import math
import platform
import statistics
import time

import cv2
import numpy as np

from mmexec.drivers.interfaces import CameraFrame, CameraIntrinsics
from mmexec.skills.perception.averaging import rotation_angle
from mmexec.skills.perception.markers import DetectorConfig, MarkerDetector, observe_markers
from mmexec.skills.perception.synthetic import look_at_marker, render_marker_view


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=100)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    K = CameraIntrinsics.from_fov(640, 480, 0.994837)  # the LoCoBot D435 stand-in
    L = 0.10
    rng = np.random.default_rng(args.seed)
    frames = []
    for i in range(args.frames):
        s = i / max(1, args.frames - 1)
        dist = 1.8 - 1.2 * s + rng.normal(0, 0.01)
        T = look_at_marker(dist, yaw=0.5 * math.sin(3 * s) + rng.normal(0, 0.01), pitch=0.15 + rng.normal(0, 0.01),
                           roll=0.1 * math.sin(5 * s), offset=(0.15 * math.sin(2 * s), -0.05))
        v = render_marker_view(K, T, 7, L, noise_sigma=3.0, depth_noise_sigma=0.004, rng=rng)
        frames.append((T, CameraFrame(v.rgb, v.depth, K, float(i), np.eye(4))))

    det = MarkerDetector(DetectorConfig(marker_length=L))
    ours, methods, pos_err, rot_err, found, dists = [], {}, [], [], 0, []
    for T, fr in frames:
        t0 = time.perf_counter()
        obs = observe_markers(fr, det, ids={7})
        ours.append((time.perf_counter() - t0) * 1e3)
        methods[det.last_method] = methods.get(det.last_method, 0) + 1
        if obs:
            found += 1
            pos_err.append(np.linalg.norm(obs[0].T_camera_marker[:3, 3] - T[:3, 3]) * 1e3)
            rot_err.append(math.degrees(rotation_angle(obs[0].T_camera_marker[:3, :3], T[:3, :3])))
            dists.append(float(T[2, 3]))

    # every marker wanted (no ids, as the fetch skills' look() asks): the whole image is
    # searched on every frame, so a marker newly in view is never missed
    det_all = MarkerDetector(DetectorConfig(marker_length=L))
    all_ms = []
    for _, fr in frames:
        t0 = time.perf_counter()
        observe_markers(fr, det_all)
        all_ms.append((time.perf_counter() - t0) * 1e3)

    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    ref = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50), params)
    base = []
    for _, fr in frames:
        gray = cv2.cvtColor(fr.rgb, cv2.COLOR_RGB2GRAY)
        t0 = time.perf_counter()
        ref.detectMarkers(gray)
        base.append((time.perf_counter() - t0) * 1e3)

    print(f"machine: {platform.machine()} python {platform.python_version()} opencv {cv2.__version__} "
          f"threads {cv2.getNumThreads()}")
    print(f"frames: {len(frames)} at 640x480, marker {L} m at 0.6-1.8 m, noise 3 grey levels")
    print(f"found: {found}/{len(frames)}; paths used: {', '.join(f'{k} {v}' for k, v in sorted(methods.items()))}")
    print(f"position error mm: median {statistics.median(pos_err):.1f}, p90 {sorted(pos_err)[int(0.9 * len(pos_err)) - 1]:.1f}; "
          f"rotation error deg: median {statistics.median(rot_err):.2f}, p90 {sorted(rot_err)[int(0.9 * len(rot_err)) - 1]:.2f}")
    for lo, hi in ((0.5, 1.0), (1.0, 1.4), (1.4, 1.9)):
        sel = [i for i, d in enumerate(dists) if lo <= d < hi]
        if sel:
            print(f"  {lo:.1f}-{hi:.1f} m: {len(sel)} frames, position median {statistics.median(pos_err[i] for i in sel):.1f} mm, "
                  f"rotation median {statistics.median(rot_err[i] for i in sel):.2f} deg, max {max(rot_err[i] for i in sel):.2f} deg")
    print(f"OpenCV default detector (SUBPIX), detection only: median {statistics.median(base):.2f} ms")
    print(f"ours, detection + pose + depth refinement: median {statistics.median(ours):.2f} ms, "
          f"p90 {sorted(ours)[int(0.9 * len(ours)) - 1]:.2f} ms, max {max(ours):.2f} ms")
    print(f"ours, every marker wanted (whole image each frame): median {statistics.median(all_ms):.2f} ms, "
          f"p90 {sorted(all_ms)[int(0.9 * len(all_ms)) - 1]:.2f} ms")
    print(f"marker_pose_ms: {statistics.median(ours):.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
