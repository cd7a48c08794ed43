"""``--mcap`` and ``mmexec log export`` (issue 13): a recorded run read back with the
``mcap`` library has every channel, its messages in time order, and counts that follow
from the event log (every record on the events and log channels, a tree snapshot per
request start and per clock instant with node changes, one scan and frame per reading a
skill took); the conversion of the run's log afterwards holds the same event-derived
messages; a seeded sim run with ``--mcap`` writes its recorded event log record for
record; bad input is one line and exit 2."""

from __future__ import annotations

import io
import json
import subprocess
import sys
from collections import Counter
from contextlib import redirect_stderr, redirect_stdout
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np
from mcap.reader import make_reader

from mmexec.drivers.interfaces import OccupancyGrid, Pose2D, Robot
from mmexec.executive.cli import main
from mmexec.executive.config import LoadedConfig, build_robot
from mmexec.executive.eventlog import read_log
from mmexec.executive.logtools import SAME_INSTANT
from mmexec.executive.recording.channels import CHANNELS
from mmexec.executive.recording.foxglove_server import DEFAULT_FOXGLOVE
from mmexec.executive.recording.layout import layout_json
from mmexec.executive.recording.session import Recording
from mmexec.executive.runner import ArgMark, Request, Runner, RunOptions

ROOT = Path(__file__).resolve().parents[2]
MOCK = ROOT / "config" / "mock.yaml"
SENSE_TICKS = 6

#: A test skill module: reads the lidar and the camera once a tick for ``ticks`` ticks and
#: publishes a planned path (the world key the streams show), as a navigation skill would.
SKILLS = '''
from mmexec.skills.base import Param, skill

@skill("fg_sense", params=[Param("ticks", int, required=True, doc="ticks")], needs=("camera", "lidar"))
def fg_sense(ctx, ticks):
    """Read the lidar and the camera every tick; publish a path."""
    ctx.world["nav.path"] = [(0.0, 0.0), (0.5, 0.0), (0.5, 0.5)]
    for _ in range(ticks):
        ctx.robot.lidar.scan()
        ctx.robot.camera.frame()
        yield
    return {}
'''

MISSION = f'''
mission: fg_test
requests:
  item: {{type: int, doc: "any number"}}
tree:
  sequence:
    - skill: report
      params: {{message: "item {{request.item}}"}}
    - skill: fg_sense
      params: {{ticks: {SENSE_TICKS}}}
    - skill: drive_to
      params: {{x: 0.4, y: 0.0}}
'''


def _setup(tmp: Path) -> tuple[Path, Path]:
    """The test mission and a mock config loading the test skill module."""
    (tmp / "fg_skills.py").write_text(SKILLS)
    mission = tmp / "fg_test.yaml"
    mission.write_text(MISSION)
    config = tmp / "mock_fg.yaml"
    config.write_text(MOCK.read_text().replace("  modules: []", "  modules: [fg_skills]\n  paths: [.]"))
    return mission, config


def _with_map(loaded: LoadedConfig) -> Robot:
    """The mock robot with a small occupancy map (the mock has none of its own)."""
    robot = build_robot(loaded, seed=0, options={"gui": False, "record": None})
    grid = np.zeros((20, 30), dtype=np.int8)
    grid[0, :] = 100
    grid[5:8, 5:8] = -1
    robot.occupancy = OccupancyGrid(grid, 0.1, Pose2D(-1.0, -1.0, 0.0))
    return robot


def _messages(path: Path) -> list[tuple[str, int, bytes]]:
    """(topic, log time [ns], data) in the order they were written."""
    with open(path, "rb") as fh:
        return [(ch.topic, m.log_time, m.data) for _, ch, m in make_reader(fh).iter_messages(log_time_order=False)]


def _expected_tree(records: list[dict[str, Any]]) -> int:
    """Snapshots the tree channel must hold: one per request start, one per clock instant
    (of a request) at which a node changed."""
    n, last = 0, None
    for r in records:
        if r["event"] == "request_start":
            n, last = n + 1, None
        elif r["event"] == "node_status":
            key = round(r["t"] / SAME_INSTANT)
            if key != last:
                n, last = n + 1, key
    return n


def test_a_recorded_mock_run_has_every_channel_in_time_order(tmp_path: Path) -> None:
    mission, config = _setup(tmp_path)
    log_path, mcap_path = tmp_path / "run.jsonl", tmp_path / "run.mcap"
    runner = Runner(RunOptions(mission=mission, config=config, log_path=log_path, seed=0,
                               requests=[Request({"item": "1"}, ArgMark("--request", 1, 1))]),
                    out=io.StringIO(), err=io.StringIO(), robot_factory=_with_map)
    runner.prepare()
    rec = Recording(mcap=mcap_path)
    rec.attach(runner)
    try:
        assert runner.run() == 0
    finally:
        rec.close()
    records = read_log(log_path)
    msgs = _messages(mcap_path)
    with open(mcap_path, "rb") as fh:
        summary = make_reader(fh).get_summary()
    assert summary is not None
    assert sorted(c.topic for c in summary.channels.values()) == sorted(s.topic for s in CHANNELS)
    counts = Counter(topic for topic, _, _ in msgs)
    assert set(counts) == {s.topic for s in CHANNELS}, "every channel has messages"
    times = [t for _, t, _ in msgs]
    assert times == sorted(times), "messages are written in time order"
    assert counts["/mmexec/events"] == counts["/mmexec/log"] == len(records)
    assert [json.loads(d) for topic, _, d in msgs if topic == "/mmexec/events"] == records
    assert counts["/mmexec/tree"] == _expected_tree(records)
    assert counts["/scan"] == counts["/camera"] == SENSE_TICKS  # each reading the skill took, once
    assert counts["/map"] == 1 and counts["/path"] == 1
    assert counts["/tf"] == counts["/pose"] + counts["/scan"] + counts["/camera"]
    assert counts["/pose"] >= 10  # every tick (20 Hz of clock time), the drive included
    last_tree = json.loads([d for topic, _, d in msgs if topic == "/mmexec/tree"][-1])
    assert {n["status"] for n in last_tree["nodes"] if n["parent"] is None} == {"SUCCESS"}
    start = next(r for r in records if r["event"] == "run_start")
    end = records[-1]
    assert times[0] >= int(datetime.fromisoformat(start["started"]).timestamp()) * 10**9
    assert times[-1] - times[0] == round(end["t"] * 1e9) - round(start["t"] * 1e9)

    # the run's log, converted afterwards, holds the same event-derived messages
    out = tmp_path / "export.mcap"
    stdout = io.StringIO()
    with redirect_stdout(stdout):
        assert main(["log", "export", str(log_path), "--mcap", str(out)]) == 0
    assert f"wrote {out}: " in stdout.getvalue()
    exported = _messages(out)
    assert exported == [m for m in msgs if m[0].startswith("/mmexec/")]
    with open(out, "rb") as fh:
        exported_summary = make_reader(fh).get_summary()
    assert exported_summary is not None and len(exported_summary.channels) == len(CHANNELS)


def _cli(args: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        code = main(args)
    return code, out.getvalue(), err.getvalue()


def test_bad_recording_options_are_one_line_and_exit_2(tmp_path: Path) -> None:
    mission = ROOT / "trees" / "demo_mock.yaml"
    taken = tmp_path / "taken.mcap"
    taken.write_bytes(b"keep me")
    base = ["run", str(mission), "--config", str(MOCK), "--request", "item=1", "--log", str(tmp_path / "a.jsonl")]
    code, _, err = _cli(base + ["--mcap", str(taken)])
    assert code == 2 and err.strip() == f"{taken}:1:1: --mcap: already exists; pass --overwrite to replace it"
    assert taken.read_bytes() == b"keep me" and not (tmp_path / "a.jsonl").exists()
    code, _, err = _cli(base + ["--foxglove", "localhost"])
    assert code == 2 and err.strip() == ("--foxglove: expected HOST:PORT with a port in 0..65535, e.g. "
                                         f"{DEFAULT_FOXGLOVE}, got 'localhost'")
    # a run that never starts (its --log exists) leaves no recording behind
    (tmp_path / "b.jsonl").write_text("")
    code, _, err = _cli(["run", str(mission), "--config", str(MOCK), "--request", "item=1", "--log",
                         str(tmp_path / "b.jsonl"), "--mcap", str(tmp_path / "b.mcap")])
    assert code == 2 and "--log: already exists" in err and not (tmp_path / "b.mcap").exists()
    code, _, err = _cli(["log", "export", str(tmp_path / "b.jsonl"), "--mcap", str(taken)])
    assert code == 2 and err.strip().endswith("--mcap: already exists; pass --overwrite to replace it")
    code, out, _ = _cli(["log", "export", str(tmp_path / "b.jsonl"), "--mcap", str(taken), "--overwrite"])
    assert code == 0 and out.startswith(f"wrote {taken}: 0 messages") and taken.read_bytes()[:8] == b"\x89MCAP0\r\n"


def test_the_cli_default_foxglove_address_is_the_servers() -> None:
    from mmexec.executive.cli import _parser

    args = _parser().parse_args(["run", "m.yaml", "--config", "c.yaml", "--foxglove"])
    assert args.foxglove == DEFAULT_FOXGLOVE


def test_the_shipped_layout_is_the_generated_one() -> None:
    shipped = ROOT / "docs" / "foxglove" / "mmexec-layout.json"
    assert shipped.read_text() == layout_json()
    text = shipped.read_text()
    for topic in ("/map", "/scan", "/camera", "/mmexec/tree", "/mmexec/log", "/mmexec/events"):
        assert f'"{topic}' in text


def test_a_seeded_sim_run_with_mcap_writes_its_recorded_event_log(tmp_path: Path) -> None:
    """tests/e2e/test_same_behaviour.py's ur5e_nominal case, recorded: the recording
    reads no sensor a skill did not read, so the event log is the recorded one."""
    sys.path.insert(0, str(ROOT / "tests" / "e2e"))
    try:
        from test_same_behaviour import GOLDEN, _normalised  # type: ignore[import-not-found]
    finally:
        sys.path.remove(str(ROOT / "tests" / "e2e"))
    log, mcap = tmp_path / "sim.jsonl", tmp_path / "sim.mcap"
    exe = Path(sys.executable).with_name("mmexec")
    res = subprocess.run([str(exe), "run", str(ROOT / "trees" / "fetch_item.yaml"), "--config",
                          str(ROOT / "config" / "ur5e_sim.yaml"), "--seed", "7", "--request", "item=3",
                          "--log", str(log), "--mcap", str(mcap)],
                         capture_output=True, text=True, timeout=600, check=False)
    assert res.returncode == 0, res.stdout + res.stderr
    got, want = _normalised(log), _normalised(GOLDEN / "ur5e_nominal.jsonl")
    got[0].pop("config_sha256")
    want[0].pop("config_sha256", None)
    assert got == want
    counts = Counter(topic for topic, _, _ in _messages(mcap))
    assert counts["/mmexec/events"] == len(got) and counts["/map"] == 1
    assert counts["/camera"] > 0 and counts["/pose"] > 0  # the search's frames, the drive


def test_a_failed_write_stops_the_recording_not_the_caller(tmp_path: Path, caplog: Any) -> None:
    """A full disk: the first failed write is kept and logged once; later messages are
    dropped, the file is closed, nothing raises."""
    import errno

    from mmexec.executive.recording.channels import Recorder
    from mmexec.executive.recording.mcapfile import McapFile

    out = McapFile(tmp_path / "full.mcap").open()
    assert out._writer is not None

    def full(*args: Any, **kw: Any) -> None:
        raise OSError(errno.ENOSPC, "No space left on device")

    out._writer.add_message = full  # type: ignore[method-assign]
    rec = Recorder(out)
    for seq in range(3):
        rec.record({"event": "report", "seq": seq, "t": 0.1 * seq, "message": "m"}, 0.1 * seq)
    rec.close()
    assert out.closed and out.error is not None and out.error.errno == errno.ENOSPC
    assert [r.levelname for r in caplog.records if "write failed" in r.getMessage()] == ["ERROR"]
