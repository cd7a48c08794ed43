"""Commands that print to standard output, run as processes whose stdout reader has gone
(``mmexec show ... | head``): they exit 141 quietly, never ``internal error:
BrokenPipeError`` nor Python's "Exception ignored ... BrokenPipeError" at exit.

The pipe's read end is closed before the command starts, so the first write that reaches
the pipe fails: inside a ``print`` for output larger than the stdout buffer (a replay of
many frames), or at the final flush for a few lines (validate)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from mmexec.config.brokenpipe import EXIT_BROKEN_PIPE

MMEXEC = Path(sys.executable).with_name("mmexec")


def run_into_closed_pipe(*argv: str | Path, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    """Run ``mmexec ARGV`` with stdout a pipe whose reader has already gone."""
    read_end, write_end = os.pipe()
    os.close(read_end)
    try:
        return subprocess.run([str(MMEXEC), *map(str, argv)], stdout=write_end, stderr=subprocess.PIPE,
                              stdin=subprocess.DEVNULL, text=True, timeout=120, cwd=cwd, check=False)
    finally:
        os.close(write_end)


def assert_quiet_exit(res: subprocess.CompletedProcess[str]) -> None:
    assert (res.returncode, res.stderr) == (EXIT_BROKEN_PIPE, "")


@pytest.fixture(scope="module")
def long_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An event log of 40 requests of 3 frames each: a replay far larger than the 8 KiB
    stdout buffer, so the broken pipe surfaces inside a print."""
    nodes = ["m", *(f"m/step{i}" for i in range(8))]
    records: list[dict[str, object]] = [{"event": "run_start", "seq": 0, "t": 0.0, "mission": "m.yaml", "requests": 40}]
    for index in range(1, 41):
        t0 = 10.0 * index
        records.append({"event": "request_start", "t": t0, "index": index, "of": 40, "request": {"item": index},
                        "nodes": nodes})
        for k, path in enumerate(nodes):
            records.append({"event": "node_status", "t": t0 + k % 3, "path": path, "old": "INVALID", "new": "RUNNING"})
        records.append({"event": "request_end", "t": t0 + 2, "index": index, "outcome": "success", "duration": 2.0})
    records.append({"event": "run_end", "t": 500.0, "outcome": "ok", "exit_code": 0})
    path = tmp_path_factory.mktemp("pipe") / "long.jsonl"
    path.write_text("".join(json.dumps(r) + "\n" for r in records))
    return path


def test_log_replay_into_a_closed_pipe(long_log: Path) -> None:
    assert_quiet_exit(run_into_closed_pipe("log", "replay", long_log))


def test_log_summary_into_a_closed_pipe(long_log: Path) -> None:
    assert_quiet_exit(run_into_closed_pipe("log", "summary", long_log))


def test_show_and_validate_into_a_closed_pipe(repo_root: Path) -> None:
    mission = repo_root / "trees" / "demo_mock.yaml"
    assert_quiet_exit(run_into_closed_pipe("show", mission))
    assert_quiet_exit(run_into_closed_pipe("validate", mission, "--config", repo_root / "config" / "mock.yaml"))


def test_campaign_into_a_closed_pipe(repo_root: Path, tmp_path: Path) -> None:
    """The campaign's first report line meets the closed pipe: it stops before any trial."""
    res = run_into_closed_pipe("campaign", repo_root / "trees" / "demo_mock.yaml", "--config",
                               repo_root / "config" / "mock.yaml", "--trials", "1", "--request", "item=1",
                               "--out", tmp_path / "camp")
    assert_quiet_exit(res)
    assert not list((tmp_path / "camp" / "trials").glob("*.json"))


def test_bad_input_still_reports_on_stderr_with_stdout_closed(tmp_path: Path) -> None:
    res = run_into_closed_pipe("log", "summary", tmp_path / "missing.jsonl")
    assert res.returncode == 2 and res.stderr == f"{tmp_path / 'missing.jsonl'}:1:1: no such file\n"
