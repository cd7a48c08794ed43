"""Trial speed: wall and CPU time per simulated second of whole seeded ``fetch_item`` trials
(default: LoCoBot with the local planner, ``lab``, ``--faults crowd``), the campaign rows of
issue 12; optionally against a baseline in the same run.

Each trial is a separate ``mmexec run`` process, as ``mmexec campaign`` runs it: the
config is the ``--config`` file with the ``--faults`` profile applied and the world drawn
per trial, trial ``i`` runs with seed ``trial_seed(--seed, i)`` and requests the world's
item ``i mod n``. Its CPU time (user + system, from the child's rusage) and wall time are
measured, its sim clock is its event log's last time stamp.

``--baseline REV`` runs the same trials with the code of git revision ``REV`` (exported
with ``git archive``), ``--baseline-sim KEY=VALUE`` with a changed ``sim:`` key (dotted,
YAML value; with or without ``--baseline``): baseline and current trials alternate, so
both see the same load on a shared machine, and each pair's event logs are compared
record by record (wall-clock fields left out) to show whether the robot did the same.
Run::

    .venv/bin/python benchmarks/trial_speed.py [--config FILE] [--faults P] [--trials N]
        [--seed S] [--baseline REV] [--baseline-sim KEY=VALUE ...] [--sim KEY=VALUE ...]

The last line is ``trial_realtime_factor: X``: sim seconds per wall second of the current
code over all trials (CPU-time factors and the ratio to the baseline are printed above it;
on a shared machine the CPU figures are the ones to compare)."""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mmexec.executive.eventlog import read_log

ROOT = Path(__file__).resolve().parent.parent
#: event-log fields that differ between equal runs (tests/e2e/test_same_behaviour.py)
VOLATILE = ("started", "planning_ms", "pid", "argv", "log", "wall", "wall_s", "ended", "mission", "config",
            "config_sha256")


@dataclass
class Trial:
    """One measured trial: sim ``clock`` [s], ``wall`` and ``cpu`` [s], ``outcome``."""

    clock: float
    wall: float
    cpu: float
    outcome: str
    log: Path


def _yaml_value(text: str) -> Any:
    from mmexec.config.yamlload import load_yaml_text

    return load_yaml_text(f"v: {text}", "<value>")["v"]


def _set(section: dict[str, Any], dotted: str, value: Any) -> None:
    *path, last = dotted.split(".")
    for key in path:
        section = section.setdefault(key, {})
    section[last] = value


def trial_config(config: Path, faults: str, sets: list[str], out: Path) -> tuple[Path, tuple[int, ...]]:
    """Write the trial config (``faults`` profile applied, world drawn per trial, ``sets``
    applied to ``sim:``) to ``out``; returns its path and the world's item markers."""
    import yaml  # writing only

    from mmexec.config.yamlload import load_yaml
    from mmexec.executive.campaign.faults import apply_fault_profile, load_fault_profile
    from mmexec.executive.campaign.jsondata import plain
    from mmexec.sim.backend import item_markers

    cfg = apply_fault_profile(load_yaml(config), load_fault_profile(faults), randomize=True)
    for s in sets:
        key, _, value = s.partition("=")
        _set(cfg.setdefault("sim", {}), key, _yaml_value(value))
    out.mkdir(parents=True, exist_ok=True)
    path = out / "config.yaml"
    path.write_text(yaml.safe_dump(plain(cfg), sort_keys=False, default_flow_style=None))
    return path, item_markers(cfg.get("sim"))


def export(repo: Path, rev: str, where: Path) -> Path:
    """A ``PYTHONPATH`` folder whose ``mmexec`` package is revision ``rev`` of ``repo``."""
    tree = where / "tree"
    tree.mkdir(parents=True)
    archive = subprocess.run(["git", "-C", str(repo), "archive", rev], check=True, capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(tree)], input=archive, check=True)
    (where / "mmexec").symlink_to(tree)
    return where


def run_trial(pythonpath: Path, cwd: Path, config: Path, seed: int, item: int, log: Path) -> Trial:
    """One ``mmexec run`` of ``fetch_item`` with the package at ``pythonpath``."""
    env = {**os.environ, "PYTHONPATH": str(pythonpath)}
    code = "import sys; from mmexec.executive.cli import main; sys.argv[0] = 'mmexec'; sys.exit(main())"
    cmd = [sys.executable, "-c", code, "run", "trees/fetch_item.yaml", "--config", str(config), "--seed", str(seed),
           "--request", f"item={item}", "--request-timeout", "600", "--log", str(log)]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    res = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if res.returncode not in (0, 1) or not log.exists():
        raise SystemExit(f"trial_speed: seed {seed}: mmexec run exited {res.returncode}: {res.stderr.strip()[-400:]}")
    recs = read_log(log)
    outcome = next((r["outcome"] for r in reversed(recs) if r.get("event") == "request_end"), "none")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return Trial(float(recs[-1]["t"]), wall, cpu, outcome, log)


def same_log(a: Path, b: Path) -> bool:
    """Whether two event logs hold the same records, the VOLATILE fields left out."""
    def norm(p: Path) -> list[dict[str, Any]]:
        return [{k: v for k, v in r.items() if k not in VOLATILE} for r in read_log(p)]

    return norm(a) == norm(b)


def _summary(name: str, trials: list[Trial]) -> tuple[float, float]:
    clock = sum(t.clock for t in trials)
    wall = sum(t.wall for t in trials)
    cpu = sum(t.cpu for t in trials)
    print(f"{name}: {len(trials)} trials, {clock:.1f} s sim, {wall:.1f} s wall, {cpu:.1f} s cpu: "
          f"realtime factor {clock / wall:.1f} wall, {clock / cpu:.1f} cpu; "
          f"{wall / len(trials):.1f} s wall a trial")
    return wall, cpu


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", default=str(ROOT / "config" / "locobot_sim_local.yaml"))
    ap.add_argument("--faults", default="crowd", help="fault profile, as mmexec campaign --faults (default crowd)")
    ap.add_argument("--trials", type=int, default=4)
    ap.add_argument("--seed", type=int, default=0, help="campaign seed (trial seeds derive from it)")
    ap.add_argument("--sim", action="append", default=[], metavar="KEY=VALUE", help="set a sim: key (current code)")
    ap.add_argument("--baseline", metavar="REV", help="git revision to compare against")
    ap.add_argument("--repo", default=str(ROOT), help="the git checkout --baseline comes from (default: this one)")
    ap.add_argument("--baseline-sim", action="append", default=[], metavar="KEY=VALUE",
                    help="set a sim: key for the baseline trials")
    args = ap.parse_args()
    from mmexec.config.yamlload import InputError
    from mmexec.executive.campaign.seeds import trial_seed

    compare = args.baseline is not None or bool(args.baseline_sim)
    with tempfile.TemporaryDirectory(prefix="trial_speed_") as tmp:
        work = Path(tmp)
        try:
            cfg, markers = trial_config(Path(args.config), args.faults, args.sim, work / "cur")
            base_cfg = trial_config(Path(args.config), args.faults, args.sim + args.baseline_sim, work / "base")[0]
        except InputError as e:
            raise SystemExit(f"trial_speed: {e}") from None
        (work / "pp").mkdir()
        (work / "pp" / "mmexec").symlink_to(ROOT)
        cur_pp, cur_root = work / "pp", ROOT
        base_pp, base_root = cur_pp, ROOT
        if args.baseline is not None:
            base_pp = export(Path(args.repo), args.baseline, work / "rev")
            base_root = base_pp / "tree"
        print(f"trial_speed: {args.trials} trials of {Path(args.config).name} --faults {args.faults}, seed {args.seed}"
              + (f"; baseline {args.baseline or 'this code'} {' '.join(args.baseline_sim)}" if compare else ""),
              flush=True)
        cur: list[Trial] = []
        base: list[Trial] = []
        same = 0
        for i in range(args.trials):
            seed, item = trial_seed(args.seed, i), markers[i % len(markers)]
            if compare:
                base.append(run_trial(base_pp, base_root, base_cfg, seed, item, work / f"base-{i}.jsonl"))
            cur.append(run_trial(cur_pp, cur_root, cfg, seed, item, work / f"cur-{i}.jsonl"))
            c = cur[-1]
            line = f"trial {i} seed {seed} item={item}: {c.clock:.1f} s sim, {c.outcome}, {c.wall:.1f} s wall, {c.cpu:.1f} s cpu"
            if compare:
                b = base[-1]
                eq = same_log(b.log, c.log)
                same += eq
                line += (f"; baseline {b.clock:.1f} s sim, {b.outcome}, {b.wall:.1f} s wall, {b.cpu:.1f} s cpu; "
                         f"same event log: {'yes' if eq else 'no'}")
            print(line, flush=True)
        wall, cpu = _summary("current", cur)
        if compare:
            bwall, bcpu = _summary("baseline", base)
            print(f"same event log in {same}/{args.trials} trials")
            clock, bclock = sum(t.clock for t in cur), sum(t.clock for t in base)
            # per simulated second: trials that part ways run for different sim times
            print(f"speedup (baseline / current, per sim second): {(bcpu / bclock) / (cpu / clock):.2f} cpu, "
                  f"{(bwall / bclock) / (wall / clock):.2f} wall")
        print(f"trial_realtime_factor: {sum(t.clock for t in cur) / wall:.1f}")


if __name__ == "__main__":
    main()
