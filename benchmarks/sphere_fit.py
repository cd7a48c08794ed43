"""Sphere barycentre benchmark (thesis Algorithm 1.2) on analytically rendered depth images.

Each trial renders the exact depth image of a sphere (ray/sphere per pixel, pinhole
640x480, hfov 0.995 rad: the LoCoBot D435 stand-in) of radius 35-45 mm, centre 0.5-1.0 m
away anywhere in the view, then spoils it the way a stereo depth camera and a cluttered
plant do: a straight occluding edge leaves 20-60 % of the sphere's image disc visible (drawn per trial), depth
noise sigma = 2 mm per metre of depth (1 mm at 0.5 m, 2 mm at 1 m; half white, half
spatially correlated), 10 % holes (half around the specular spot), 5 % outliers (half
flying pixels 2-30 cm behind, half uniform in 0.3-1.5 m).

The segmentation mask is the visible disc (what the colour mask would give). Timed per
trial: :func:`fit_sphere` on the masked points (back-projection not included; it is
printed separately). Compared on the same points: the naive centroid of the points
(Algorithm 1.3 line 8), the centroid pushed back by the radius along its ray (DemoV1's
clicked surface point pushed back, with the centroid for the click), and the same
least-squares refinement on all points from there, without sample consensus (what the
outliers cost). The spoiling is :func:`render_sphere_view`. Prints the figures and LAST ``sphere_center_error_mm: X`` (our median).

    .venv/bin/python benchmarks/sphere_fit.py [--trials 500] [--seed 0] [--holes 0.1] [--outliers 0.05]
        [--noise 0.002]
"""

from __future__ import annotations

import argparse
import itertools
import os
import platform
import statistics
import time

import numpy as np

from mmexec.drivers.interfaces import CameraIntrinsics
from mmexec.skills.perception.sphere import (
    SphereFitConfig,
    depth_to_points,
    fit_sphere,
    refine_sphere,
    render_sphere_view,
)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=500)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--holes", type=float, default=0.10, help="fraction of visible pixels without depth")
    ap.add_argument("--outliers", type=float, default=0.05, help="fraction of visible pixels with a wrong depth")
    ap.add_argument("--noise", type=float, default=0.002, help="depth noise sigma per metre of depth")
    args = ap.parse_args(argv)
    K = CameraIntrinsics.from_fov(640, 480, 0.994837)
    cfg = SphereFitConfig(radius_range=(0.03, 0.05))
    rng = np.random.default_rng(args.seed)
    fit_rng = np.random.default_rng(args.seed + 1)
    ours, naive, pushed, plain_ls, t_fit, cpu_fit, t_pts, npts = [], [], [], [], [], [], [], []
    clamped = 0
    cases: list[tuple[float, float]] = []
    failed = 0
    for _ in range(args.trials):
        radius = rng.uniform(0.035, 0.045)
        dist = rng.uniform(0.5, 1.0)
        u, v = rng.uniform(0.15, 0.85) * K.width, rng.uniform(0.15, 0.85) * K.height
        ray = np.array([(u - K.cx) / K.fx, (v - K.cy) / K.fy, 1.0])
        centre = ray / np.linalg.norm(ray) * dist
        visible = rng.uniform(0.2, 0.6)
        cases.append((visible, dist))
        view = render_sphere_view(K, centre, radius, rng, visible=visible, noise_per_metre=args.noise,
                                  holes=args.holes, outliers=args.outliers)
        t0 = time.perf_counter()
        pts = depth_to_points(view.depth, K, mask=view.mask)
        t1, c1 = time.perf_counter(), time.process_time()
        fit = fit_sphere(pts, cfg, fit_rng)
        t2, c2 = time.perf_counter(), time.process_time()
        cpu_fit.append((c2 - c1) * 1e3)
        t_pts.append((t1 - t0) * 1e3)
        t_fit.append((t2 - t1) * 1e3)
        npts.append(len(pts))
        g = pts.mean(axis=0)
        naive.append(np.linalg.norm(g - centre) * 1e3)
        start = g + g / np.linalg.norm(g) * radius
        pushed.append(np.linalg.norm(start - centre) * 1e3)
        c_ls, _, _ = refine_sphere(pts, start, radius, cfg.radius_range, 20)
        plain_ls.append(np.linalg.norm(c_ls - centre) * 1e3)
        if fit is None:
            failed += 1
            ours.append(float("inf"))
            continue
        clamped += fit.radius_clamped
        ours.append(np.linalg.norm(fit.centre - centre) * 1e3)

    def q(a: list[float], p: float) -> float:
        return float(np.percentile(np.asarray(a), p))

    cpu = "unknown"
    if os.path.exists("/proc/cpuinfo"):
        with open("/proc/cpuinfo") as f:
            names = [ln.split(":", 1)[1].strip() for ln in f if ln.startswith("model name")]
        cpu = names[0] if names else cpu
    print(f"machine: {platform.machine()} {cpu}, nproc {os.cpu_count()}, python {platform.python_version()}, "
          f"numpy {np.__version__}")
    print(f"trials: {args.trials} spheres r 35-45 mm at 0.5-1.0 m, 20-60 % of the disc visible, "
          f"noise {args.noise * 1e3:g} mm/m, {args.holes:.0%} holes, {args.outliers:.0%} outliers; points per sphere: median {statistics.median(npts):.0f}, "
          f"min {min(npts)}, max {max(npts)}")
    print(f"config: {cfg}")
    for name, e in (("ours (MLESAC + LS)", ours), ("naive centroid", naive), ("centroid + r along ray", pushed),
                    ("LS on all points", plain_ls)):
        print(f"{name:24s} centre error mm: median {q(e, 50):.2f}, p95 {q(e, 95):.2f}, max {max(e):.2f}")
    err = np.asarray(ours)
    vis, dis = np.array(cases).T
    for name, key, edges in (("visible", vis, (0.2, 0.333, 0.467, 0.6)), ("distance m", dis, (0.5, 0.667, 0.833, 1.0))):
        for lo, hi in itertools.pairwise(edges):
            sel = err[(key >= lo) & (key <= hi)]
            print(f"  ours, {name} {lo:.2f}-{hi:.2f}: {len(sel)} trials, median {np.median(sel):.2f} mm, "
                  f"p95 {np.percentile(sel, 95):.2f} mm")
    print(f"fits failed: {failed}; radius clamped: {clamped}")
    print(f"time per fit ms: median {statistics.median(t_fit):.2f}, p95 {q(t_fit, 95):.2f}, max {max(t_fit):.2f}; "
          f"back-projection median {statistics.median(t_pts):.2f}; CPU time per fit median "
          f"{statistics.median(cpu_fit):.2f} (all threads of the process)")
    print(f"sphere_center_error_mm: {q(ours, 50):.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
