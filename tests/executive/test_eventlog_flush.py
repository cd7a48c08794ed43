"""Event log: JSON lines flushed per record, readable after a crash."""

from __future__ import annotations

import enum
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mmexec.executive.eventlog import EventLog, LogFormatError, read_log, to_jsonable


class Colour(enum.Enum):
    RED = "red"


def test_each_record_is_on_disk_before_the_next_write(tmp_path: Path) -> None:
    path = tmp_path / "run.jsonl"
    t = [0.0]
    log = EventLog(path, clock=lambda: t[0]).open()
    log.write("run_start", mission="m.yaml")
    # read through a separate file handle: the record must already be there
    assert json.loads(path.read_text().splitlines()[0]) == {"event": "run_start", "seq": 0, "t": 0.0, "mission": "m.yaml"}
    t[0] = 1.5
    log.emit("node_status", path="a/b", old="INVALID", new="RUNNING")
    lines = path.read_text().splitlines()
    assert len(lines) == 2 and json.loads(lines[1])["t"] == 1.5
    log.close()
    assert log.closed


def test_records_survive_a_killed_process(tmp_path: Path) -> None:
    path = tmp_path / "crash.jsonl"
    code = (
        "import os, sys\n"
        "from mmexec.executive.eventlog import EventLog\n"
        f"log = EventLog({str(path)!r}).open()\n"
        "for i in range(5):\n"
        "    log.write('tick', i=i)\n"
        "os._exit(9)\n"  # no close, no atexit, no buffer flush at exit
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, timeout=60, check=False)
    assert proc.returncode == 9
    assert [r["i"] for r in read_log(path)] == [0, 1, 2, 3, 4]


def test_read_log_skips_truncated_last_line_only(tmp_path: Path) -> None:
    path = tmp_path / "t.jsonl"
    path.write_text('{"event":"a","seq":0}\n{"event":"b","se')
    assert [r["event"] for r in read_log(path)] == ["a"]
    path.write_text('{"event":"a","seq":0}\nnot json\n{"event":"b","seq":1}\n')
    with pytest.raises(LogFormatError, match=r"t.jsonl:2: not a JSON event record"):
        read_log(path)
    path.write_text('[1, 2]\n')
    with pytest.raises(LogFormatError, match="expected a JSON object"):
        read_log(path)


def test_to_jsonable_handles_robot_values() -> None:
    value = {
        "status": Colour.RED,
        "q": np.array([1.0, 2.0]),
        "n": np.int64(3),
        "faults": frozenset({"b", "a"}),
        "inf": math.inf,
        "path": Path("x/y"),
        "tuple": (1, 2),
    }
    assert to_jsonable(value) == {
        "status": "red", "q": [1.0, 2.0], "n": 3, "faults": ["a", "b"], "inf": "inf", "path": "x/y", "tuple": [1, 2],
    }
    json.dumps(to_jsonable(value), allow_nan=False)


def test_memory_only_log_keeps_records() -> None:
    log = EventLog(None)
    seen = []
    log.add_listener(seen.append)
    log.write("x", a=1)
    log.write("y")
    assert [r["event"] for r in log.records] == ["x", "y"] and [r["seq"] for r in seen] == [0, 1]
    log.close()


def test_open_creates_parent_dirs(tmp_path: Path) -> None:
    path = tmp_path / "deep" / "er" / "run.jsonl"
    with EventLog(path) as log:
        log.write("x")
    assert path.exists() and os.path.getsize(path) > 0
