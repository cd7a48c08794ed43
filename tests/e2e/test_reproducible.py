"""A seeded sim run is reproducible to the last digit: the same `mmexec run ... --seed`
twice (two processes, as a campaign's trial is re-run alone) writes the same event log,
clock times included, whatever the machine's load. Arm planning runs off the tick thread;
on the simulator's stepped clock a tick waits for it, so it always costs one tick of
clock time (see skills/fetch/arm.py off_tick)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from simkit import MISSION, REPO, log_records

#: wall-clock fields, which differ between two runs by nature
WALL_FIELDS = ("started", "planning_ms", "pid", "argv", "log", "wall", "wall_s", "ended")


def _run(tmp_path: Path, name: str) -> list[dict]:
    cfg = tmp_path / "locobot_rand.yaml"
    if not cfg.exists():
        text = (REPO / "config" / "locobot_sim.yaml").read_text()
        assert "\nsim:\n" in text
        cfg.write_text(text.replace("\nsim:\n", "\nsim:\n  randomize: true\n", 1))
    log = tmp_path / f"{name}.jsonl"
    exe = Path(sys.executable).with_name("mmexec")
    res = subprocess.run([str(exe), "run", str(MISSION), "--config", str(cfg), "--seed", "3356100361",
                          "--request", "item=5", "--log", str(log)],
                         capture_output=True, text=True, timeout=300, check=False)
    assert res.returncode == 0, res.stdout + res.stderr
    return log_records(log, WALL_FIELDS)


def test_the_same_seed_gives_the_same_event_log(tmp_path: Path) -> None:
    a = _run(tmp_path, "a")
    b = _run(tmp_path, "b")
    assert any(r["event"] == "arm_plan" for r in a)  # planning happened, off the tick thread
    assert len(a) == len(b)
    for ra, rb in zip(a, b):
        assert ra == rb
