"""An event log is never shared or silently replaced, and a failed write stops the robot.

The file rules of :class:`~mmexec.executive.eventlog.EventLog` (exclusive creation,
``--overwrite``, no symlinks, an exclusive lock, regular files only), how the runner and
the command line report a path that cannot be used (one located line, exit 2), unique
default names, and a write failure mid-run (disk full, injected at the one ``write(2)``
the log makes) on the mock base: the base is stopped, one line says so, exit 1, and
every line of the log is still a whole JSON record.
"""

from __future__ import annotations

import errno
import io
import json
import os
import re
import signal
import subprocess
import sys
from datetime import UTC, datetime
from pathlib import Path

import pytest
from test_signals import DRIVE_AND_REPORT, START_LIMIT, finish, mmexec, wait_until
from test_signals import MOCK_CONFIG as CONFIG

from mmexec.executive import runner as runner_mod
from mmexec.executive.eventlog import (
    EventLog,
    LogExistsError,
    LogInUseError,
    LogOpenError,
    read_log,
)
from mmexec.executive.runner import Progress, Runner, RunOptions

SHORT = """\
mission: short
tree:
  skill: report
  params: {message: hello}
"""


def files(tmp_path: Path, mission: str = SHORT) -> tuple[Path, Path]:
    m, c = tmp_path / "mission.yaml", tmp_path / "config.yaml"
    m.write_text(mission)
    c.write_text(CONFIG)
    return m, c


def strict_records(path: Path) -> list[dict]:
    """Every line of ``path`` parsed as JSON: no truncated line is tolerated here."""
    data = path.read_bytes()
    assert not data or data.endswith(b"\n"), data[-80:]
    return [json.loads(line) for line in data.splitlines()]


def one_error_line(res, expected: str) -> None:  # type: ignore[no-untyped-def]
    assert res.rc == 2, (res.out, res.err)
    assert res.err.splitlines() == [expected], res.err
    assert "Traceback" not in res.err


# --------------------------------------------------------------------------- EventLog file rules


def test_an_existing_file_is_refused_and_left_alone(tmp_path: Path) -> None:
    path = tmp_path / "run.jsonl"
    path.write_text("precious\n")
    with pytest.raises(LogExistsError) as ei:
        EventLog(path).open()
    assert str(ei.value) == f"{path}: already exists"
    assert path.read_text() == "precious\n"


def test_overwrite_replaces_a_regular_file(tmp_path: Path) -> None:
    path = tmp_path / "run.jsonl"
    path.write_text("old content that is longer than the new log\n" * 10)
    with EventLog(path, overwrite=True) as log:
        log.write("x", a=1)
    assert strict_records(path) == [{"event": "x", "seq": 0, "a": 1}]


@pytest.mark.parametrize("overwrite", [False, True])
@pytest.mark.parametrize("dangling", [False, True])
def test_a_symlink_is_never_followed(tmp_path: Path, overwrite: bool, dangling: bool) -> None:
    target = tmp_path / "elsewhere.txt"
    if not dangling:
        target.write_text("do not touch\n")
    link = tmp_path / "run.jsonl"
    link.symlink_to(target)
    with pytest.raises(LogOpenError, match="is a symbolic link"):
        EventLog(link, overwrite=overwrite).open()
    assert link.is_symlink()
    if dangling:
        assert not target.exists()  # not created through the link
    else:
        assert target.read_text() == "do not touch\n"


def test_a_second_writer_is_refused_and_the_first_log_kept(tmp_path: Path) -> None:
    path = tmp_path / "run.jsonl"
    first = EventLog(path).open()
    first.write("run_start")
    with pytest.raises(LogInUseError, match="is in use"):
        EventLog(path, overwrite=True).open()
    first.write("run_end")
    first.close()
    assert [r["event"] for r in strict_records(path)] == ["run_start", "run_end"]
    # once closed, the lock is gone: replacing it on purpose works
    with EventLog(path, overwrite=True) as again:
        again.write("fresh")
    assert [r["event"] for r in strict_records(path)] == ["fresh"]


def test_the_lock_holds_against_another_process(tmp_path: Path) -> None:
    path = tmp_path / "run.jsonl"
    code = ("import sys\nfrom mmexec.executive.eventlog import EventLog, LogInUseError\n"
            f"try:\n    EventLog({str(path)!r}, overwrite=True).open()\n"
            "except LogInUseError as e:\n    print(e)\n    sys.exit(3)\n")
    with EventLog(path) as log:
        log.write("mine")
        res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=False)
    assert res.returncode == 3, res.stderr
    assert "is in use" in res.stdout
    assert [r["event"] for r in strict_records(path)] == ["mine"]


@pytest.mark.parametrize("make, expected", [
    (lambda p: p.mkdir(), "is a directory, expected an event log file"),
    (lambda p: os.mkfifo(p), "is not a regular file"),
])
def test_not_a_regular_file_is_refused(tmp_path: Path, make, expected: str) -> None:  # type: ignore[no-untyped-def]
    path = tmp_path / "run.jsonl"
    make(path)
    for overwrite in (False, True):
        with pytest.raises(LogOpenError) as ei:
            EventLog(path, overwrite=overwrite).open()  # a FIFO nobody reads must not block
        assert ei.value.reason == expected and not isinstance(ei.value, LogExistsError)


def test_unusable_paths_say_why_in_one_line(tmp_path: Path) -> None:
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    with pytest.raises(LogOpenError) as ei:
        EventLog(blocker / "run.jsonl").open()
    assert str(ei.value) == f"{blocker / 'run.jsonl'}: cannot create its folder {blocker}: File exists"
    long_name = tmp_path / ("x" * 300 + ".jsonl")
    with pytest.raises(LogOpenError) as ei:
        EventLog(long_name).open()
    assert str(ei.value).endswith(": cannot open for writing: File name too long") and "\n" not in str(ei.value)


# --------------------------------------------------------------------------- write failures


class DiskFull:
    """Stands in for ``write(2)``: takes bytes until ``budget`` is spent, then (like a
    filling disk) a short write and then ENOSPC."""

    def __init__(self, budget: int) -> None:
        self.budget = budget

    def __call__(self, fd: int, data: bytes) -> int:
        if self.budget <= 0:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        n = os.write(fd, bytes(data[: self.budget]))
        self.budget -= n
        return n


def test_a_failed_write_leaves_only_whole_records(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "run.jsonl"
    log = EventLog(path, keep=True).open()
    seen: list[str] = []
    log.add_listener(lambda r: seen.append(r["event"]))
    log.write("one", pad="x" * 10)
    size = path.stat().st_size
    monkeypatch.setattr(EventLog, "_write_some", staticmethod(DiskFull(size // 2)))
    log.write("two", pad="y" * 100)  # half of it reaches the disk, then ENOSPC
    assert log.error is not None and log.error.errno == errno.ENOSPC
    log.write("three")  # not written, but counted and still seen by listeners
    assert log.dropped == 2 and seen == ["one", "two", "three"] and len(log.records) == 3
    log.close()
    assert [r["event"] for r in strict_records(path)] == ["one"]
    assert [r["event"] for r in read_log(path)] == ["one"]


def test_disk_full_mid_run_stops_the_base_and_exits_1(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    m, c = files(tmp_path, DRIVE_AND_REPORT)
    log = tmp_path / "run.jsonl"
    out, err = io.StringIO(), io.StringIO()
    r = Runner(RunOptions(mission=m, config=c, log_path=log), out=out, err=err, progress=Progress(out, enabled=False))
    r.prepare()
    speeds: list[float] = []

    def fill_the_disk(record: dict) -> None:  # the third report (0.3 s of driving): the disk fills
        assert r.robot is not None and r.robot.base is not None
        if record["event"] == "report":
            speeds.append(r.robot.base.state().v)
            if len(speeds) == 3:
                monkeypatch.setattr(EventLog, "_write_some", staticmethod(DiskFull(40)))

    r.add_log_listener(fill_the_disk)
    assert r.run() == 1
    robot = r.robot
    assert robot is not None and robot.base is not None
    assert len(speeds) == 3 and speeds[-1] > 0.2  # it was moving when the disk filled
    assert robot.base.stops > 0 and robot.safe_stops >= 1 and robot.closed
    assert robot.base.state().v == 0.0 or abs(robot.base.state().v) < 1e-3
    assert err.getvalue().splitlines() == [(f"mmexec: event log {log}: No space left on device (ENOSPC); "
                                            "the robot was stopped and the run ended")]
    assert [x.outcome for x in r.results] == ["error"]
    assert r.results[0].reason == "event log write failed: No space left on device (ENOSPC)"
    records = strict_records(log)
    assert records[-1]["event"] == "report" and "run_end" not in [x["event"] for x in records]


def test_disk_full_before_the_first_request_serves_nothing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    m, c = files(tmp_path)
    log = tmp_path / "run.jsonl"
    monkeypatch.setattr(EventLog, "_write_some", staticmethod(DiskFull(0)))
    out, err = io.StringIO(), io.StringIO()
    r = Runner(RunOptions(mission=m, config=c, log_path=log), out=out, err=err, progress=Progress(out, enabled=False))
    r.prepare()
    assert r.run() == 1
    assert r.results == [] and r.robot is not None and r.robot.closed
    assert "No space left on device (ENOSPC)" in err.getvalue()
    assert log.read_bytes() == b""


# --------------------------------------------------------------------------- runner and command line


def test_default_log_names_are_unique(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    name = runner_mod.default_log_path(Path("trees/fetch_item.yaml"))
    assert re.fullmatch(rf"mmexec-logs/fetch_item-\d{{8}}T\d{{6}}\.\d{{3}}Z-{os.getpid()}\.jsonl", str(name))

    class Frozen(datetime):
        @classmethod
        def now(cls, tz=None):  # type: ignore[no-untyped-def, override]
            return datetime(2025, 3, 1, 14, 15, 3, 42_999, tzinfo=UTC)

    monkeypatch.setattr(runner_mod, "datetime", Frozen)
    monkeypatch.chdir(tmp_path)
    m, c = files(tmp_path)
    taken = Path(f"mmexec-logs/mission-20250301T141503.042Z-{os.getpid()}.jsonl")
    taken.parent.mkdir()
    taken.write_text("someone else's\n")
    paths = []
    for _ in range(2):  # the same millisecond, the same process: still two logs
        out = io.StringIO()
        r = Runner(RunOptions(mission=m, config=c), out=out, err=io.StringIO(), progress=Progress(out, enabled=False))
        r.prepare()
        assert r.run() == 0
        paths.append(r.log_path)
    assert taken.read_text() == "someone else's\n"
    assert [str(p) for p in paths] == [f"mmexec-logs/mission-20250301T141503.042Z-{os.getpid()}-{i}.jsonl"
                                       for i in (1, 2)]


def test_cli_refuses_an_existing_log_unless_overwrite(run_cli, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    m, c = files(tmp_path)
    log = tmp_path / "run.jsonl"
    log.write_text("yesterday's run\n")
    res = run_cli("run", m, "--config", c, "--log", log)
    one_error_line(res, f"{log}:1:1: --log: already exists; pass --overwrite to replace it")
    assert log.read_text() == "yesterday's run\n"
    res = run_cli("run", m, "--config", c, "--log", log, "--overwrite")
    assert res.rc == 0, res.err
    assert [r["event"] for r in strict_records(log)][-1] == "run_end"


def test_cli_refuses_unusable_log_paths(run_cli, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    m, c = files(tmp_path)
    folder = tmp_path / "logs"
    folder.mkdir()
    one_error_line(run_cli("run", m, "--config", c, "--log", folder),
                   f"{folder}:1:1: --log: is a directory, expected an event log file")
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    one_error_line(run_cli("run", m, "--config", c, "--log", blocker / "run.jsonl"),
                   f"{blocker / 'run.jsonl'}:1:1: --log: cannot create its folder {blocker}: File exists")
    target = tmp_path / "target.txt"
    target.write_text("keep\n")
    (tmp_path / "link.jsonl").symlink_to(target)
    one_error_line(run_cli("run", m, "--config", c, "--log", tmp_path / "link.jsonl", "--overwrite"),
                   f"{tmp_path / 'link.jsonl'}:1:1: --log: is a symbolic link "
                   "(an event log is never written through one)")
    assert target.read_text() == "keep\n"


def test_cli_second_writer_is_refused_while_a_run_writes(run_cli, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    m, c = files(tmp_path, DRIVE_AND_REPORT)
    log = tmp_path / "run.jsonl"
    with mmexec("run", m, "--config", c, "--log", log) as proc:
        assert wait_until(lambda: log.exists() and b'"message":"driving"' in log.read_bytes(), START_LIMIT, proc)
        one_error_line(run_cli("run", m, "--config", c, "--log", log, "--overwrite"),
                       f"{log}:1:1: --log: is in use: another process holds its lock (another run writing it?)")
        proc.send_signal(signal.SIGINT)
        _out, err = finish(proc)
    assert proc.returncode == 130, err
    records = strict_records(log)  # the first run's log, whole: never truncated by the second
    assert records[0]["event"] == "run_start" and records[-1]["event"] == "run_end"


def test_demo_replaces_its_own_log_in_its_folder(run_cli, tmp_path: Path,  # type: ignore[no-untyped-def]
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    seen: list[RunOptions] = []
    monkeypatch.setattr(Runner, "prepare", lambda self: seen.append(self.options))
    monkeypatch.setattr(Runner, "run", lambda self: 0)
    res = run_cli("demo", "--out", tmp_path, "--no-record")
    assert res.rc == 0, res.err
    assert [(o.log_path, o.overwrite) for o in seen] == [(tmp_path / "events.jsonl", True)]


def test_campaign_resume_reruns_an_interrupted_trial_into_its_log(tmp_path: Path) -> None:
    from mmexec.executive.campaign import CampaignOptions, run_campaign

    m, c = files(tmp_path)
    opts = CampaignOptions(mission=m, config=c, trials=1, out=tmp_path / "camp", seed=1, workers=1, progress=False)
    with open(os.devnull, "w") as null:
        _, results = run_campaign(opts, out=null)
        assert [r.outcome for r in results] == ["success"]
        assert "--overwrite" not in results[0].command and "--log" not in results[0].command
        trials = tmp_path / "camp" / "trials"
        (trials / "0000.json").unlink()  # as if the campaign was stopped while trial 0 ran
        (trials / "0000.jsonl").write_text('{"event":"run_start","seq":0}\n'
                                           '{"event":"run_end","seq":1,"outcome":"interrupted","exit_code":130}\n')
        again, results = run_campaign(opts, out=null)
    assert again.ran == 1 and [r.outcome for r in results] == ["success"], results
    assert [r["event"] for r in strict_records(trials / "0000.jsonl")][-1] == "run_end"
