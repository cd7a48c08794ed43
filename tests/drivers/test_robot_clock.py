"""The robot backend's clock counts seconds since the robot was built, as the sim's and
the mock's do, so the event log's ``t`` is seconds since the start of the run on every
backend (it was raw ``time.monotonic()``, i.e. seconds since the machine booted)."""

from __future__ import annotations

import json
import time
from pathlib import Path

import pytest

from mmexec.config.yamlload import load_yaml_text
from mmexec.drivers import robot as robot_backend

#: what time.monotonic() reads on a machine that has been up for about 11 days [s]
UPTIME = 1.0e6


@pytest.fixture
def long_uptime(monkeypatch: pytest.MonkeyPatch) -> list[float]:
    """time.monotonic() = UPTIME + an offset the test moves (nothing sleeps)."""
    offset = [0.0]
    monkeypatch.setattr(time, "monotonic", lambda: UPTIME + offset[0])
    return offset


def test_the_robot_clock_starts_at_zero_when_the_robot_is_built(long_uptime: list[float]) -> None:
    robot = robot_backend.build(load_yaml_text("name: bare\n", "c.yaml"), profile={}, seed=None, options={})
    try:
        assert robot.clock.now() == 0.0
        long_uptime[0] += 2.5
        assert robot.clock.now() == pytest.approx(2.5)
    finally:
        robot.close()


def test_event_log_t_is_seconds_since_the_start_on_the_robot(run_cli, tmp_path: Path, monkeypatch) -> None:
    real = time.monotonic
    monkeypatch.setattr(time, "monotonic", lambda: UPTIME + real())
    mission = tmp_path / "hello.yaml"
    mission.write_text("mission: hello\ntree:\n  skill: report\n  params: {message: hi}\n")
    cfg = tmp_path / "bare.yaml"
    cfg.write_text("backend: robot\nrobot: {name: bare}\n")
    log = tmp_path / "run.jsonl"
    res = run_cli("run", mission, "--config", cfg, "--log", log)
    assert res.rc == 0, res.err
    records = [json.loads(line) for line in log.read_text().splitlines()]
    stamps = [r["t"] for r in records if "t" in r]
    assert stamps and all(0.0 <= t < UPTIME / 2 for t in stamps), stamps
    run_end = next(r for r in records if r["event"] == "run_end")
    assert 0.0 <= run_end["duration"] < UPTIME / 2
