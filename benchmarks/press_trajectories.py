"""The thesis's trajectory figure for the button presser: every straight-line trajectory
of a press_buttons run, planned against executed.

``press_buttons`` writes one ``press_trajectory`` event per button to the run's event log
(skills/buttons/panel.py): for the press and for the release, the pressing tip's
``planned`` positions (the timed joint trajectory's samples through the forward
kinematics) and its ``executed`` positions (the joints the arm measured each tick through
the same kinematics), [t, x, y, z] in the button's frame in mm (z along the face normal, 0
at the cap's rest position; x, y across the face). This script draws, per trajectory, the
tip's distance along the normal over time (planned and executed), and the executed tip's
deviation across the line; and it tabulates per trajectory the largest lateral deviation,
the end-point error along the normal and the executed duration against the planned one.

Usage (from the repository root)::

    .venv/bin/python benchmarks/press_trajectories.py --run          # run the mission (UR5e sim, seed 0) and draw
    .venv/bin/python benchmarks/press_trajectories.py LOG             # draw a logged run

Writes benchmarks/results/press_trajectories.png and prints a Markdown table; the last
line is ``press_lateral_max_mm <the largest lateral deviation of any executed trajectory>``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / "benchmarks" / "results" / "press_trajectories.png"


def run_mission(folder: Path, seed: int) -> Path:
    """Run trees/press_buttons.yaml on config/ur5e_sim.yaml; returns its event log."""
    log = folder / "press.jsonl"
    subprocess.run([str(REPO / ".venv" / "bin" / "mmexec"), "run", str(REPO / "trees" / "press_buttons.yaml"),
                    "--config", str(REPO / "config" / "ur5e_sim.yaml"), "--seed", str(seed), "--log", str(log),
                    "--overwrite"], check=True, cwd=REPO)
    return log


def trajectories(log: Path) -> list[tuple[str, str, np.ndarray, np.ndarray]]:
    """(button, phase, planned, executed) of every press and release in the log, in order."""
    out = []
    for line in log.read_text().splitlines():
        rec = json.loads(line)
        if rec.get("event") != "press_trajectory":
            continue
        for phase in ("press", "release"):
            tr = rec[phase]
            out.append((rec["button"], phase, np.array(tr["planned"], dtype=float), np.array(tr["executed"], dtype=float)))
    return out


def measures(planned: np.ndarray, executed: np.ndarray) -> dict[str, float]:
    """Largest lateral deviation of the executed tip [mm], its end error along the normal
    [mm], and the planned and executed durations [s] (executed: until within 0.2 mm of
    the planned end along the normal)."""
    lateral = float(np.max(np.hypot(executed[:, 1], executed[:, 2])))
    end = float(executed[-1, 3] - planned[-1, 3])
    near = np.flatnonzero(np.abs(executed[:, 3] - planned[-1, 3]) < 0.2)
    return {"lateral_max_mm": lateral, "end_error_mm": end, "planned_s": float(planned[-1, 0]),
            "executed_s": float(executed[near[0], 0]) if len(near) else float("nan")}


def draw(trs: list[tuple[str, str, np.ndarray, np.ndarray]], out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(trs)
    fig, axes = plt.subplots(2, n, figsize=(2.6 * n, 5.0), sharey="row", squeeze=False)
    for k, (button, phase, pl, ex) in enumerate(trs):
        ax = axes[0, k]
        ax.plot(pl[:, 0], pl[:, 3], "-", color="#48c", lw=2, label="planned")
        ax.plot(ex[:, 0], ex[:, 3], "o", color="#c44", ms=3, label="executed")
        ax.axhline(-0.7 * 6.0, color="#999", lw=0.8, ls=":")
        ax.set_title(f"{button} {phase}", fontsize=9)
        ax.set_xlabel("t [s]")
        lat = axes[1, k]
        lat.plot(pl[:, 0], np.hypot(pl[:, 1], pl[:, 2]), "-", color="#48c", lw=2)
        lat.plot(ex[:, 0], np.hypot(ex[:, 1], ex[:, 2]), "o-", color="#c44", ms=3, lw=0.8)
        lat.set_xlabel("t [s]")
    axes[0, 0].set_ylabel("tip along the normal [mm]\n(0: cap at rest; dotted: switch point)")
    axes[1, 0].set_ylabel("tip off the line [mm]")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle("press_buttons: straight-line trajectories, planned vs executed (UR5e sim)", fontsize=10)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=90)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("log", nargs="?", type=Path, help="an event log of trees/press_buttons.yaml")
    ap.add_argument("--run", action="store_true", help="run the mission first (config/ur5e_sim.yaml)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args(argv)
    if args.run == (args.log is not None):
        ap.error("give a LOG or --run")
    with tempfile.TemporaryDirectory() as tmp:
        log = run_mission(Path(tmp), args.seed) if args.run else args.log
        trs = trajectories(log)
    if not trs:
        print(f"{log}: no press_trajectory events", file=sys.stderr)
        return 1
    draw(trs, args.out)
    rows: list[dict[str, Any]] = []
    print("| trajectory | samples planned | samples executed | lateral max [mm] | end error along the normal [mm] "
          "| planned / executed [s] |")
    print("|---|---:|---:|---:|---:|---|")
    for button, phase, pl, ex in trs:
        m = measures(pl, ex)
        rows.append(m)
        print(f"| {button} {phase} | {len(pl)} | {len(ex)} | {m['lateral_max_mm']:.2f} | {m['end_error_mm']:+.2f} | "
              f"{m['planned_s']:.2f} / {m['executed_s']:.2f} |")
    print(f"figure: {args.out}")
    print(f"press_lateral_max_mm {max(r['lateral_max_mm'] for r in rows):.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
