"""The figure of a logged navigation run (docs/img/nav_run.png), and the ground truth of a
campaign's trials in numbers.

A run with the local planner on writes what it planned and did to its event log
(``nav_plan``: every path, why it was planned; ``nav_tick``: the estimated pose, the
command, the smallest barrier value h, the tracked people) and, with ``sim.truth_log``,
what really happened to the ground-truth sidecar (``mmexec.sim.truth``: the true pose,
clearance and gap to every person per tick, the contacts). This script draws both:

* left: the map the robot was given (grey), the world's obstacles (orange: the unmapped
  ones, which only the lidar found), the people's true tracks (blue) and where the robot
  tracked them (dots), every path it planned (dashed: the first of each drive; red: the
  re-plans round what the map did not show), the robot's true path (coloured by time)
  and any contact (x);
* right: the commanded and DWA forward speed and the social speed scale (top), the
  smallest barrier value h and the true gap to the nearest person (bottom) over time (as
  the UR3e paper's figure 11 shows its planners' paths and velocities).

Usage (from the repository root)::

    .venv/bin/python benchmarks/nav_figure.py --run                 # run the scenario, draw docs/img/nav_run.png
    .venv/bin/python benchmarks/nav_figure.py LOG TRUTH --world W   # draw a logged run
    .venv/bin/python benchmarks/nav_figure.py --truth-summary DIR   # a campaign's navigation measures

``--run`` fetches item 2 in the ``corridors`` world (config/locobot_corridors_sim.yaml,
seed 0) with a parcel the map does not show in the strip east of the long desk and the
world's visitor walking the 1.7 m corridor: the robot re-plans round the parcel through
the 1.2 m corridor and gives way to the visitor on its way to the placing stage.
The last printed line is ``nav_run_s <clock seconds of the request>``.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from mmexec.executive.campaign.navtruth import (
    log_measures,
    nav_report_lines,
    summarize_nav,
    truth_measures,
)
from mmexec.executive.eventlog import read_log
from mmexec.sim.world import load_world

log = logging.getLogger("nav_figure")

REPO = Path(__file__).resolve().parents[1]
#: the parcel of the ``--run`` scenario: not in the map, filling the strip east of the desk
PARCEL = "  - {name: parcel, pose: [8.82, 3.2, 0.0], size: [0.9, 0.5, 0.8], unmapped: true}\n"


def run_scenario(folder: Path, seed: int = 0, item: int = 2) -> tuple[Path, Path, Path]:
    """Run the ``--run`` scenario with ``mmexec run`` in ``folder``; returns the event
    log, the truth sidecar and the world file."""
    world = folder / "corridors_parcel.yaml"
    text = (REPO / "sim" / "worlds" / "corridors.yaml").read_text()
    world.write_text(text.replace("obstacles:\n", "obstacles:\n" + PARCEL, 1))
    cfg_text = (REPO / "config" / "locobot_corridors_sim.yaml").read_text()
    truth = folder / "truth.jsonl"
    cfg = folder / "corridors.yaml"
    cfg.write_text(cfg_text.replace("  world: corridors\n", f"  world: {world}\n  truth_log: {truth}\n", 1))
    events = folder / "events.jsonl"
    exe = Path(sys.executable).with_name("mmexec")
    res = subprocess.run([str(exe), "run", str(REPO / "trees" / "fetch_item.yaml"), "--config", str(cfg),
                          "--seed", str(seed), "--request", f"item={item}", "--log", str(events)],
                         capture_output=True, text=True, check=False, timeout=1800)
    log.info("mmexec run: exit %d\n%s", res.returncode, res.stdout.strip())
    if res.returncode not in (0, 1):
        raise RuntimeError(f"mmexec run failed ({res.returncode}): {res.stderr.strip()}")
    return events, truth, world


def _read_jsonl(path: Path) -> list[dict[str, Any]]:
    return [json.loads(ln) for ln in path.read_text().splitlines() if ln.strip()]


def _box(ax: Any, pose: Sequence[float], size: Sequence[float], **style: Any) -> None:
    """A rotated rectangle (box footprint) in map coordinates."""
    x, y, yaw = pose
    hx, hy = size[0] / 2, size[1] / 2
    c, s = math.cos(yaw), math.sin(yaw)
    corners = [(x + c * a - s * b, y + s * a + c * b) for a, b in ((hx, hy), (-hx, hy), (-hx, -hy), (hx, -hy), (hx, hy))]
    xs, ys = zip(*corners)
    ax.fill(xs, ys, **style)


def draw(events: Path, truth: Path, world: str, out: Path) -> dict[str, float]:
    """Draw the run (module docstring) to ``out``; returns its numbers (clock seconds,
    re-plans, contacts, smallest true gap to a person and clearance)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    recs = read_log(events)
    tr = _read_jsonl(truth)
    start = next(r for r in tr if r["event"] == "truth_start")
    ticks = [r for r in tr if r["event"] == "truth"]
    end = next((r for r in tr if r["event"] == "truth_end"), {})
    w = load_world(world)
    grid = w.occupancy(0.05)
    fig = plt.figure(figsize=(15, 6.4))
    gs = fig.add_gridspec(2, 2, width_ratios=[1.45, 1.0])
    ax = fig.add_subplot(gs[:, 0])
    bx = fig.add_subplot(gs[0, 1])
    cx = fig.add_subplot(gs[1, 1], sharex=bx)

    # the map the robot was given, then what was really there
    ext = (grid.origin.x, grid.origin.x + grid.width * grid.resolution,
           grid.origin.y, grid.origin.y + grid.height * grid.resolution)
    ax.imshow(np.where(np.asarray(grid.data) >= 50, 0.55, 1.0), origin="lower", extent=ext, cmap="gray",
              vmin=0.0, vmax=1.0, interpolation="nearest")
    for o in start["obstacles"]:
        if o["unmapped"]:
            _box(ax, o["pose"], o["size"], color="tab:orange", alpha=0.85, label="unmapped (lidar only)")
    for d in w.spec.depots:
        _box(ax, d.pose, d.size, color="tab:green", alpha=0.5, label="placing stage (depot)")
    # people: true tracks and the robot's tracks of them
    if ticks and "people" in ticks[0]:
        ppl = np.array([r["people"] for r in ticks])
        for k, pe in enumerate(start["people"]):
            ax.plot(ppl[:, k, 0], ppl[:, k, 1], color="tab:blue", lw=0.8, alpha=0.5,
                    label="people (true)" if k == 0 else None)
            ax.add_patch(plt.Circle(tuple(ppl[-1, k]), pe["radius"], color="tab:blue", alpha=0.3))
    seen = np.array([p[:2] for r in recs if r.get("event") == "nav_tick" for p in r["people"]]).reshape(-1, 2)
    if len(seen):
        ax.scatter(seen[::3, 0], seen[::3, 1], s=3, color="navy", alpha=0.35, label="people (tracked)")
    # plans
    first_of_drive = True
    replans = 0
    for r in recs:
        if r.get("event") == "base_status" and r.get("status") == "idle":
            first_of_drive = True
        if r.get("event") != "nav_plan" or not r.get("found") or r.get("why") == "dock":
            continue
        pts = np.array(r["points"])
        if r["why"] in ("blocked", "recovery", "contact"):
            replans += 1
            ax.plot(pts[:, 0], pts[:, 1], color="tab:red", lw=1.2, ls=":", label="re-plan" if replans == 1 else None)
        elif first_of_drive:
            ax.plot(pts[:, 0], pts[:, 1], color="0.25", lw=1.0, ls="--",
                    label="A* on the map" if not ax.get_legend_handles_labels()[1].count("A* on the map") else None)
        first_of_drive = False
    # the robot's true path, coloured by time
    xy = np.array([r["pose"][:2] for r in ticks])
    t = np.array([r["t"] for r in ticks])
    sc = ax.scatter(xy[:, 0], xy[:, 1], c=t, s=2, cmap="viridis")
    fig.colorbar(sc, ax=ax, fraction=0.03, pad=0.01, label="clock time [s] (robot's true path)")
    for c in (r for r in tr if r["event"] == "contact"):
        ax.plot(*c["pose"][:2], "kx", ms=9, mew=2, label="contact (truth: base or arm)")
    handles, labels = ax.get_legend_handles_labels()
    uniq = dict(zip(labels, handles))
    ax.legend(uniq.values(), uniq.keys(), loc="upper left", fontsize=7, framealpha=0.9)
    ax.set_aspect("equal")
    ax.set_xlim(ext[0], ext[1])
    ax.set_ylim(ext[2], ext[3])
    ax.set_xlabel("x [m] (map)")
    ax.set_ylabel("y [m]")
    ax.set_title(f"world {start['world']!r}: paths, obstacles and people")

    # speeds (top); barrier and true gap (bottom) over time
    nav = [r for r in recs if r.get("event") == "nav_tick"]
    tn = np.array([r["t"] for r in nav])
    bx.plot(tn, [r["ref"][0] for r in nav], ".", ms=1.5, color="tab:olive", alpha=0.6, label="v of the DWA [m/s]")
    bx.plot(tn, [r["cmd"][0] for r in nav], ".", ms=1.5, color="tab:purple", label="v sent (after the filter) [m/s]")
    bx.plot(tn, [r["scale"] for r in nav], ".", ms=1.0, color="tab:cyan", label="social speed scale")
    bx.set_ylim(-0.05, 1.1)
    bx.legend(loc="upper right", fontsize=7)
    bx.set_title("local planner: forward speed (ticks while driving)")
    hs = [(r["t"], r["h"]) for r in nav if r["h"] is not None]
    if hs:
        th, hv = zip(*hs)
        cx.plot(th, hv, ".", ms=1.5, color="tab:red", label="smallest barrier h [m²] (tracked circles)")
    if ticks and "gaps" in ticks[0]:
        cx.plot(t, [min(r["gaps"]) for r in ticks], color="tab:blue", lw=0.8, label="true gap to the nearest person [m]")
    cx.plot(t, [r["clearance"] for r in ticks], color="0.4", lw=0.8, label="true clearance to static geometry [m]")
    cx.axhline(0.0, color="k", lw=0.5)
    cx.set_ylim(-0.3, 2.0)
    cx.set_xlabel("clock time [s]")
    cx.legend(loc="upper right", fontsize=7)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    request_end = next((r for r in recs if r.get("event") == "request_end"), {})
    return {"seconds": float(request_end.get("duration", t[-1] if len(t) else 0.0)), "replans": replans,
            "contacts": float(end.get("contacts", 0)),
            "min_gap": min((g for g in (end.get("min_gap") or {}).values() if g is not None), default=math.inf),
            "min_clearance": float(end.get("min_clearance") or math.nan)}


def truth_summary(folder: Path) -> str:
    """A campaign's navigation measures in numbers, from its ground truth
    (``folder/truth/SEED.jsonl``) and its trials' event logs (``folder/trials``): the
    per-trial rows (contacts and with what, the smallest true gap to a person, the
    smallest true clearance, the filter's smallest logged h), then the campaign's
    "Navigation (ground truth)" table as ``mmexec campaign`` writes it into report.md
    (:mod:`mmexec.executive.campaign.navtruth`). ``folder`` may also be the truth folder
    itself (no event logs then). Returns the text (markdown)."""
    truth_dir = folder / "truth" if (folder / "truth").is_dir() else folder
    logs = {}
    for res in sorted((folder / "trials").glob("*.json")) if truth_dir != folder else ():
        data = json.loads(res.read_text())
        logs[str(data["seed"])] = Path(data["log"]).with_name(res.stem + ".jsonl")
    rows, measures = [], []
    for path in sorted(truth_dir.glob("*.jsonl")):
        m = truth_measures(path)
        log_path = logs.get(path.stem)
        if log_path is not None and log_path.is_file():
            m.update(log_measures(_read_jsonl(log_path)))
        measures.append(m)
        if "truth_ticks" not in m:
            rows.append(f"| {path.stem} | (no ticks) | | | |")
            continue
        what = ", ".join(f"{b} x{n}" for b, n in sorted(m["contact_bodies"].items())) or "none"
        gap = "-" if m["min_gap_person"] is None else f"{m['min_gap_person']:.3f}"
        h = f"{m['nav_min_h']:.4f}" if "nav_min_h" in m else "-"
        rows.append(f"| {path.stem} | {what} | {gap} | {m['min_clearance']:.3f} | {h} |")
    head = ["| seed | contacts | min gap to a person [m] | min clearance [m] | filter's min h [m^2] |",
            "|---|---|---:|---:|---:|"]
    return "\n".join(head + rows + [""] + nav_report_lines(summarize_nav(measures)))


def main(argv: list[str] | None = None) -> int:
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n", 1)[0])
    ap.add_argument("log", nargs="?", type=Path, help="event log of the run")
    ap.add_argument("truth", nargs="?", type=Path, help="its ground-truth sidecar (sim.truth_log)")
    ap.add_argument("--world", help="the run's world (shipped name or file; default: the sidecar's world name)")
    ap.add_argument("--run", action="store_true", help="run the corridors scenario first (module docstring)")
    ap.add_argument("--out", type=Path, default=REPO / "docs" / "img" / "nav_run.png")
    ap.add_argument("--truth-summary", type=Path, metavar="DIR", help="print a campaign's navigation measures")
    args = ap.parse_args(argv)
    if args.truth_summary is not None:
        print(truth_summary(args.truth_summary))
        return 0
    with tempfile.TemporaryDirectory(prefix="nav_figure_") as tmp:
        if args.run:
            events, truth, world = run_scenario(Path(tmp))
            world_name = str(world)
        elif args.log is not None and args.truth is not None:
            events, truth = args.log, args.truth
            world_name = args.world or next(r for r in _read_jsonl(truth) if r["event"] == "truth_start")["world"]
        else:
            ap.error("give LOG and TRUTH, --run or --truth-summary")
        numbers = draw(events, truth, world_name, args.out)
    print(f"wrote {args.out}: {numbers['replans']} re-plans, {numbers['contacts']:.0f} contacts, smallest gap to a "
          f"person {numbers['min_gap']:.3f} m, smallest clearance {numbers['min_clearance']:.3f} m")
    print(f"nav_run_s {numbers['seconds']:.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
