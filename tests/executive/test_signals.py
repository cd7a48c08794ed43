"""The safety contract on a real ``mmexec run`` process (docs/cli.md, "Safety contract").

SIGINT, SIGTERM and SIGHUP halt the tree, stop the robot, close the drivers and end the
event log with ``request_end`` and ``run_end``; the exit code is 128 + the signal. A
Ctrl-C while the command is still importing exits 130 without a traceback. A slow tick
rate does not delay the halt. A full disk (here: a file size limit) stops the robot too.

The robot runs are against the Kobuki fake (the real serial protocol on a pty, served by
this test process); what is asserted is what the device saw and what the log says, with
bounds far from what the process needs (no wall-clock timing).
"""

from __future__ import annotations

import contextlib
import json
import os
import resource
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from mmexec.drivers.fakes.kobuki import KobukiFake
from mmexec.executive.eventlog import read_log

EXE = Path(sys.executable).with_name("mmexec")
#: [wall s] generous bound for a loaded machine to start the command and move the base
START_LIMIT = 90.0

DRIVE = """\
mission: drive_far
tree:
  sequence:
    - skill: report
      params: {message: started}
    - skill: drive_to
      params: {x: 100.0, y: 0.0}
"""

#: drives while writing a record every 0.1 s of clock time (a log that keeps growing)
DRIVE_AND_REPORT = """\
mission: drive_and_report
tree:
  parallel:
    - skill: drive_to
      params: {x: 100.0, y: 0.0}
    - repeat:
        sequence:
          - wait: 0.1
          - skill: report
            params: {message: driving}
      until_failure: true
"""

MOCK_CONFIG = """\
backend: mock
rate_hz: 20
mock:
  capabilities: [base]
"""


def kobuki_config(port: str) -> str:
    """A robot config with only a Kobuki base on ``port`` (the fake's pty)."""
    return ("backend: robot\nrate_hz: 20\nrobot:\n  name: signal_bot\n"
            f"  base: {{kind: kobuki, port: {port}, linear_accel: 5.0}}\n"
            "profile: {}\n")


def write_files(tmp_path: Path, mission: str, config: str) -> tuple[Path, Path, Path]:
    m, c = tmp_path / "mission.yaml", tmp_path / "config.yaml"
    m.write_text(mission)
    c.write_text(config)
    return m, c, tmp_path / "run.jsonl"


def wait_until(pred: Callable[[], bool], timeout: float, proc: subprocess.Popen[str] | None = None) -> bool:
    """Poll ``pred`` every 10 ms for up to ``timeout`` wall seconds; False at once when
    ``proc`` has ended (its output then says why)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if pred():
            return True
        if proc is not None and proc.poll() is not None:
            return pred()
        time.sleep(0.01)
    return pred()


@contextlib.contextmanager
def mmexec(*args: object, env: dict[str, str] | None = None) -> Iterator[subprocess.Popen[str]]:
    """``mmexec ARGS`` as a subprocess with piped output; killed if still running after."""
    full_env = dict(os.environ, PYTHONUNBUFFERED="1", **(env or {}))
    full_env.pop("MMEXEC_DEBUG", None)
    proc = subprocess.Popen([str(EXE), *map(str, args)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=full_env)
    try:
        yield proc
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.communicate()


def finish(proc: subprocess.Popen[str]) -> tuple[str, str]:
    out, err = proc.communicate(timeout=START_LIMIT)
    return out or "", err


@pytest.fixture
def fake() -> Iterator[KobukiFake]:
    with KobukiFake() as f:
        yield f


def moving(fake: KobukiFake, at_least: int = 1) -> Callable[[], bool]:
    """The fake drives forward at ``at_least`` mm/s."""
    return lambda: fake.snapshot().speed >= at_least


def stopped(fake: KobukiFake) -> Callable[[], bool]:
    return lambda: (fake.snapshot().speed, fake.snapshot().radius) == (0, 0)


def assert_signal_ending(log: Path, sig: signal.Signals) -> list[dict]:
    """The log ends as the contract says for ``sig``; returns its records."""
    recs = read_log(log)
    names = [r["event"] for r in recs]
    halt = next(r for r in recs if r["event"] == "halt")
    assert (halt["reason"], halt["signal"]) == ("interrupt", sig.name)
    assert names.index("halt") < names.index("skill_cancel") < names.index("skill_stopped")
    ends = [r for r in recs if r["event"] == "request_end"]
    expected = "interrupted (Ctrl-C)" if sig == signal.SIGINT else f"interrupted ({sig.name})"
    assert [(e["outcome"], e["reason"]) for e in ends] == [("interrupted", expected)]
    run_end = recs[-1]
    assert run_end["event"] == "run_end", names[-5:]
    assert (run_end["outcome"], run_end["exit_code"], run_end["signal"]) == ("interrupted", 128 + sig, sig.name)
    return recs


# --------------------------------------------------------------------------- Kobuki fake


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP, signal.SIGINT], ids=lambda s: s.name)
def test_signal_stops_the_kobuki_and_ends_the_log(tmp_path: Path, fake: KobukiFake, sig: signal.Signals) -> None:
    m, c, log = write_files(tmp_path, DRIVE, kobuki_config(fake.port))
    with mmexec("run", m, "--config", c, "--log", log) as proc:
        assert wait_until(moving(fake), START_LIMIT, proc), proc.stderr and proc.stderr.read()
        if sig == signal.SIGHUP:  # as when an ssh session closes: the terminal is gone too
            assert proc.stdout is not None
            proc.stdout.close()
        proc.send_signal(sig)
        out, err = finish(proc)
    assert proc.returncode == 128 + sig, err
    assert "Traceback" not in err and err == "", err
    assert wait_until(stopped(fake), 2.0), fake.snapshot()
    assert_signal_ending(log, sig)
    if sig != signal.SIGHUP:
        assert "request 1/1 (-): interrupted" in out


def test_slow_tick_rate_does_not_delay_the_halt(tmp_path: Path, fake: KobukiFake) -> None:
    """At 1 Hz (the slowest rate a config may ask for) the runner waits 1 s between ticks;
    SIGTERM right after the first tick must halt the tree then, not at the second tick,
    and the stopping tree must be ticked again promptly, not one period later."""
    period = 1.0
    m, c, log = write_files(tmp_path, DRIVE.replace("    - skill: report\n      params: {message: started}\n", ""),
                            kobuki_config(fake.port))
    with mmexec("run", m, "--config", c, "--log", log, "--rate", 1.0 / period) as proc:
        # at drive_to's full 0.3 m/s (0.06 s of ramp), so braking takes more than one tick
        assert wait_until(moving(fake, 300), START_LIMIT, proc), proc.stderr and proc.stderr.read()
        proc.send_signal(signal.SIGTERM)
        _out, err = finish(proc)
    assert proc.returncode == 143, err
    assert wait_until(stopped(fake), 2.0), fake.snapshot()
    recs = assert_signal_ending(log, signal.SIGTERM)
    t = {r["event"]: r["t"] for r in recs if r["event"] in ("request_start", "halt", "skill_stopped")}
    # the first tick runs at request_start, the second one period later: the halt came before
    assert t["halt"] - t["request_start"] < period, t
    # braking takes a few ticks; unhurried they would come a period apart (or later)
    assert t["skill_stopped"] - t["halt"] < period, t


def test_disk_full_mid_run_stops_the_kobuki(tmp_path: Path, fake: KobukiFake) -> None:
    """The log's file size limit is reached while the base drives (EFBIG, as ENOSPC on a
    full disk): the base is stopped, one line says so, exit 1, every line stays JSON."""
    m, c, log = write_files(tmp_path, DRIVE_AND_REPORT, kobuki_config(fake.port))
    with mmexec("run", m, "--config", c, "--log", log) as proc:
        assert wait_until(moving(fake), START_LIMIT, proc), proc.stderr and proc.stderr.read()
        assert wait_until(lambda: b'"message":"driving"' in log.read_bytes(), START_LIMIT, proc)
        # a few bytes more than now: the next record is cut by the kernel mid-line
        limit = log.stat().st_size + 20
        resource.prlimit(proc.pid, resource.RLIMIT_FSIZE, (limit, limit))
        _out, err = finish(proc)
    assert proc.returncode == 1, err
    assert err.splitlines() == [(f"mmexec: event log {log}: File too large (EFBIG); "
                                 "the robot was stopped and the run ended")], err
    assert wait_until(stopped(fake), 2.0), fake.snapshot()
    data = log.read_bytes()
    assert data.endswith(b"\n") and len(data) <= limit
    records = [json.loads(line) for line in data.splitlines()]  # every line is a whole record
    assert records[-1]["event"] in ("report", "node_status", "skill_start", "skill_success")


# --------------------------------------------------------------------------- mock backend


def test_sigterm_on_the_mock_writes_the_whole_ending(tmp_path: Path) -> None:
    m, c, log = write_files(tmp_path, DRIVE, MOCK_CONFIG)
    with mmexec("run", m, "--config", c, "--log", log) as proc:
        assert wait_until(lambda: log.exists() and b'"skill":"drive_to"' in log.read_bytes(), START_LIMIT, proc)
        proc.send_signal(signal.SIGTERM)
        out, err = finish(proc)
    assert proc.returncode == 143, err
    assert err == ""
    recs = assert_signal_ending(log, signal.SIGTERM)
    assert [r["event"] for r in recs][-2:] == ["request_end", "run_end"]
    assert "request 1/1 (-): interrupted after" in out and "(interrupted)" in out


def test_second_signal_skips_the_wait(tmp_path: Path) -> None:
    """A stop that would take long (a slow arm move braking for 10000 s of clock time) is
    cut short by a second signal: ``halt_abandoned``, then the robot's safe stop."""
    mission = DRIVE.replace("skill: drive_to\n      params: {x: 100.0, y: 0.0}",
                            "skill: move_arm\n      params: {pose: far, speed_scale: 0.000001}")
    config = ("backend: mock\nrate_hz: 20\nmock:\n  capabilities: [arm]\n  arm: {stop_time: 10000.0}\n"
              "profile:\n  named_poses: {far: [1.0, 1.0, 1.0, 1.0, 1.0, 1.0]}\n")
    m, c, log = write_files(tmp_path, mission, config)
    with mmexec("run", m, "--config", c, "--log", log) as proc:
        assert wait_until(lambda: log.exists() and b'"skill":"move_arm"' in log.read_bytes(), START_LIMIT, proc)
        proc.send_signal(signal.SIGTERM)
        assert wait_until(lambda: b'"event":"skill_cancel"' in log.read_bytes(), START_LIMIT, proc)
        proc.send_signal(signal.SIGHUP)
        _out, err = finish(proc)
    assert proc.returncode == 143, err  # the first signal decides the code
    recs = read_log(log)
    assert [r["reason"] for r in recs if r["event"] == "halt_abandoned"] == ["second interrupt"]
    assert recs[-1]["event"] == "run_end" and recs[-1]["signal"] == "SIGTERM"


# --------------------------------------------------------------------------- start-up

#: the console script's own code, with an import hook that sends SIGINT to the process
#: when MODULE starts importing (so the Ctrl-C lands inside the imports, every time)
HOOKED_ENTRY = """\
import importlib.abc, os, signal, sys
MODULE = sys.argv.pop(1)
class CtrlC(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name == MODULE:
            sys.meta_path.remove(self)
            os.kill(os.getpid(), signal.SIGINT)
        return None
sys.meta_path.insert(0, CtrlC())
from mmexec.executive.cli import main
sys.exit(main())
"""


@pytest.mark.parametrize("module", ["yaml", "py_trees", "mmexec.executive.eventlog", "pybullet"])
def test_ctrl_c_during_imports_exits_130_quietly(tmp_path: Path, module: str) -> None:
    m, c, log = write_files(tmp_path, DRIVE, MOCK_CONFIG)
    res = subprocess.run([sys.executable, "-c", HOOKED_ENTRY, module, "run", m, "--config", c, "--log", log],
                         capture_output=True, text=True, timeout=START_LIMIT, check=False)
    assert res.returncode == 130, res.stderr
    assert res.stderr == "mmexec: interrupted\n"
    assert not log.exists()  # interrupted before anything was started


def test_ctrl_c_right_after_spawn_is_quiet(tmp_path: Path) -> None:
    m, c, log = write_files(tmp_path, DRIVE, MOCK_CONFIG)
    with mmexec("run", m, "--config", c, "--log", log) as proc:
        proc.send_signal(signal.SIGINT)
        _out, err = finish(proc)
    # 130 from the command, or (the signal came before Python started) killed by SIGINT:
    # both read as 130 to a shell, and nothing was started
    assert proc.returncode in (130, -signal.SIGINT), err
    assert "Traceback" not in err


def test_a_signal_the_user_ignores_stays_ignored(tmp_path: Path) -> None:
    """Under ``nohup`` SIGHUP is ignored: the run must not take it over (in-process)."""
    import io

    from mmexec.executive.runner import Progress, Runner, RunOptions

    m, c, log = write_files(tmp_path, DRIVE.replace("x: 100.0", "x: 0.5"), MOCK_CONFIG)
    seen: dict[str, object] = {}

    def look(record: dict) -> None:
        if record["event"] == "request_start":
            seen["hup"], seen["term"] = signal.getsignal(signal.SIGHUP), signal.getsignal(signal.SIGTERM)

    before_term = signal.getsignal(signal.SIGTERM)
    old = signal.signal(signal.SIGHUP, signal.SIG_IGN)
    try:
        out = io.StringIO()
        r = Runner(RunOptions(mission=m, config=c, log_path=log), out=out, err=io.StringIO(),
                   progress=Progress(out, enabled=False))
        r.add_log_listener(look)
        assert r.run() == 0
        assert signal.getsignal(signal.SIGHUP) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGHUP, old)
    assert seen["hup"] is signal.SIG_IGN
    assert callable(seen["term"]) and seen["term"] is not before_term  # SIGTERM was the runner's
    assert signal.getsignal(signal.SIGTERM) is before_term  # and is given back
