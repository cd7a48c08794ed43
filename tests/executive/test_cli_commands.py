"""The mmexec command line: exit codes, one-line errors, log tools, demo, hw delegation,
and Ctrl-C on a real subprocess."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
import types
from pathlib import Path

import pytest

from mmexec.executive.eventlog import read_log

CONFIG = """\
backend: mock
mock:
  gripper: {grasps: [false, false, false, false]}
profile:
  named_poses: {ready: [0.0, -0.5, 0.6, 0.0, 0.5, 0.0]}
"""

MISSION = """\
mission: pick
requests:
  item: {type: int}
tree:
  recovery:
    action:
      sequence:
        - skill: open_gripper
        - skill: close_gripper
          params: {expect: object}
    recovery:
      skill: move_arm
      params: {pose: ready}
    max_recoveries: 2
  name: grasp
"""

LOCATED = re.compile(r"^(\S+:\d+:\d+|--request #\d+|--param #\d+|mmexec[: ]|\S+:\d+: )")


def files(tmp_path: Path, mission: str = MISSION, config: str = CONFIG) -> tuple[Path, Path]:
    m, c = tmp_path / "m.yaml", tmp_path / "c.yaml"
    m.write_text(mission)
    c.write_text(config)
    return m, c


def assert_input_error(res, *needles: str) -> None:
    assert res.rc == 2, (res.out, res.err)
    assert "Traceback" not in res.err and res.err.strip()
    for line in res.err.strip().splitlines():
        assert LOCATED.match(line), f"unlocated error line: {line!r}"
    for n in needles:
        assert n in res.err, res.err


# --------------------------------------------------------------------------- validate


def test_validate_ok_and_with_config(run_cli, tmp_path: Path) -> None:
    m, c = files(tmp_path)
    res = run_cli("validate", m)
    assert res.rc == 0 and "ok" in res.out
    res = run_cli("validate", m, "--config", c)
    assert res.rc == 0 and "binds to backend 'mock'" in res.out


def test_validate_reports_every_problem_located(run_cli, tmp_path: Path) -> None:
    bad = MISSION.replace("skill: open_gripper", "skill: open_griper").replace("expect: object", "expect: objekt")
    m, _ = files(tmp_path, mission=bad)
    res = run_cli("validate", m)
    assert_input_error(res, "did you mean 'open_gripper'", f"{m}:8:")
    assert len(res.err.strip().splitlines()) == 2


def test_validate_config_checks_robot_capabilities(run_cli, tmp_path: Path) -> None:
    m, c = files(tmp_path)
    c.write_text(CONFIG.replace("mock:\n", "mock:\n  capabilities: [base, arm]\n"))
    res = run_cli("validate", m, "--config", c)
    assert_input_error(res, "skill 'open_gripper' needs a gripper", "skill 'close_gripper' needs a gripper")
    assert f"{m}:8:11:" in res.err


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["validate", "{tmp}/nope.yaml"], "nope.yaml:1:1: no such file"),
        (["validate", "{m}", "--config", "{tmp}/nope.yaml"], "nope.yaml:1:1: no such file"),
        (["run", "{m}", "--config", "{bad_yaml}", "--request", "item=1"], "malformed YAML"),
        (["run", "{m}", "--config", "{bad_cfg}", "--request", "item=1"], "rate_hz: expected a number"),
        (["run", "{m}", "--config", "{c}", "--request", "item"], "--request #1: request: expected KEY=VALUE"),
        (["run", "{m}", "--config", "{c}", "--request", "item=x"], "--request #1: request 1:"),
        (["run", "{m}", "--config", "{c}", "--request", "item=1", "--request", "itm=2"],
         "did you mean 'item'"),
        (["run", "{m}", "--config", "{c}"], "mmexec run (no --request given): request 1: request: missing field 'item'"),
        (["run", "{m}", "--config", "{c}", "--requests", "{reqs_bad}"], "reqs_bad.yaml:1:1: expected a YAML list"),
        (["run", "{m}", "--config", "{c}", "--requests", "{tmp}/none.yaml"], "none.yaml:1:1: no such file"),
        (["run", "{m}", "--config", "{mod_cfg}", "--request", "item=1"],
         "skills.modules[0]: cannot import 'no_such_lab_module_xyz': no such module"),
        (["run", "{m}", "--config", "{robot_cfg}", "--request", "item=1"], "robot_cfg.yaml:1:10: "),
        (["run", "{m}", "--config", "{c}", "--request", "item=1", "--param", "speed=1"], "unknown parameter"),
        (["run", "{m}"], "the following arguments are required: --config"),
        (["run", "{m}", "--config", "{c}", "--seed", "abc"], "invalid int value"),
        (["frobnicate"], "invalid choice"),
        (["log", "summary", "{tmp}/no.jsonl"], "no.jsonl:1:1: no such file"),
        (["log", "summary", "{badlog}"], "badlog.jsonl:1: not a JSON event record"),
    ],
)
def test_bad_input_is_one_line_per_problem_exit_2(run_cli, tmp_path: Path, args: list[str], needle: str) -> None:
    m, c = files(tmp_path)
    paths = {"tmp": tmp_path, "m": m, "c": c}
    for name, text in {
        "bad_yaml": "backend: [mock\n",
        "bad_cfg": "backend: mock\nrate_hz: fast\n",
        "reqs_bad": "item: 1\n",
        "mod_cfg": "backend: mock\nskills: {modules: [no_such_lab_module_xyz]}\n",
        "robot_cfg": "backend: robot\n",
    }.items():
        p = tmp_path / f"{name}.yaml"
        p.write_text(text)
        paths[name] = p
    (tmp_path / "badlog.jsonl").write_text("garbage\n{\"event\": \"x\"}\n")
    paths["badlog"] = tmp_path / "badlog.jsonl"
    res = run_cli(*[a.format(**paths) for a in args])
    assert_input_error(res, needle)


def test_requests_file(run_cli, tmp_path: Path) -> None:
    m, c = files(tmp_path, config=CONFIG.replace("[false, false, false, false]", "[]"))
    rf = tmp_path / "reqs.yaml"
    rf.write_text("- {item: 4}\n- {item: 5}\n")
    log = tmp_path / "run.jsonl"
    res = run_cli("run", m, "--config", c, "--request", "item=3", "--requests", rf, "--log", log)
    assert res.rc == 0, res.err
    assert [r["request"] for r in read_log(log) if r["event"] == "request_end"] == [{"item": 3}, {"item": 4}, {"item": 5}]
    rf.write_text("- {item: 4}\n- {item: seven}\n")
    res = run_cli("run", m, "--config", c, "--requests", rf, "--log", log)
    assert_input_error(res, f"{rf}:2:3: request 2:")


# --------------------------------------------------------------------------- run + log tools


def test_run_failure_exit_1_then_summary_and_replay(run_cli, tmp_path: Path) -> None:
    m, c = files(tmp_path)
    log = tmp_path / "run.jsonl"
    res = run_cli("run", m, "--config", c, "--request", "item=1", "--request", "item=2", "--log", log)
    # 4 scripted empty grasps: request 1 uses 3 (gives up), request 2 fails once then succeeds
    assert res.rc == 1, res.err
    assert "request 1/2 (item=1): failure" in res.out and "request 2/2 (item=2): success" in res.out
    res = run_cli("log", "summary", log)
    assert res.rc == 0
    out = res.out
    assert "request 1/2 (item=1): failure after" in out and "2 recoveries" in out
    assert "recovery 1 at" in out and "recovery 2 at" in out and "closed on nothing" in out
    assert "request 2/2 (item=2): success after" in out and "1 recovery" in out
    assert "requests: 2 served of 2, 1 succeeded (1 failure, 1 success)" in out
    assert "failure reasons:\n  1 x close_gripper: closed on nothing (expected an object)" in out
    assert "run: failed (exit 1)" in out
    res = run_cli("log", "replay", log, "--request", "2")
    assert res.rc == 0
    frames = res.out.split("── request ")
    assert len(frames) > 5 and all(f.startswith("2/2") for f in frames[1:])
    assert "✓ grasp [SUCCESS]" in frames[-1]
    assert "! recovery_attempt grasp" in res.out


def test_summary_of_a_crashed_run(run_cli, tmp_path: Path) -> None:
    log = tmp_path / "cut.jsonl"
    recs = [
        {"event": "run_start", "seq": 0, "mission": "m.yaml", "requests": 2},
        {"event": "request_start", "seq": 1, "index": 1, "of": 2, "request": {"item": 1}, "nodes": ["m"]},
        {"event": "node_status", "seq": 2, "t": 0.0, "path": "m", "old": "INVALID", "new": "RUNNING"},
    ]
    log.write_text("".join(json.dumps(r) + "\n" for r in recs) + '{"event": "node_st')
    res = run_cli("log", "summary", log)
    assert res.rc == 0
    assert "request 1/2 (item=1): unfinished" in res.out and "no run_end record" in res.out


def test_demo_runs_two_requests(run_cli, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    res = run_cli("demo", "--mock")  # the sim fetch demo (plain `demo`) is tested in tests/e2e/test_demo.py
    assert res.rc == 0, res.err
    assert "request 1/2 (item=1): success" in res.out and "1 recovery" in res.out
    assert "request 2/2 (item=2): success" in res.out
    logs = list((tmp_path / "mmexec-logs").glob("demo_mock-*.jsonl"))
    assert len(logs) == 1 and read_log(logs[0])[-1]["outcome"] == "ok"


def test_hw_delegates_or_reports_missing(run_cli, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "mmexec.drivers.hwcli", None)
    res = run_cli("hw", "scan")
    assert_input_error(res, "mmexec hw: hardware tools are not available")
    seen = []
    fake = types.ModuleType("mmexec.drivers.hwcli")
    fake.main = lambda argv: seen.append(argv) or 3
    monkeypatch.setitem(sys.modules, "mmexec.drivers.hwcli", fake)
    assert run_cli("hw", "scan", "--port", "/dev/ttyUSB0").rc == 3
    assert seen == [["scan", "--port", "/dev/ttyUSB0"]]


def test_internal_error_is_one_line_exit_1(run_cli, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from mmexec.executive import cli

    def broken(args):
        raise ZeroDivisionError("division by zero\nsecond line")

    monkeypatch.setattr(cli, "_cmd_validate", broken)
    monkeypatch.delenv("MMEXEC_DEBUG", raising=False)
    res = run_cli("validate", tmp_path / "x.yaml")
    assert res.rc == 1
    assert res.err.strip() == ("mmexec: internal error: ZeroDivisionError: division by zero; "
                               "set MMEXEC_DEBUG=1 for details")


# --------------------------------------------------------------------------- real process, Ctrl-C

LONG_MISSION = """\
mission: long
tree:
  sequence:
    - skill: report
      params: {message: started}
    - skill: drive_to
      params: {x: 1000000.0, y: 0.0}
"""


def test_ctrl_c_halts_cancels_and_exits_130(tmp_path: Path) -> None:
    m, c = files(tmp_path, mission=LONG_MISSION)
    log = tmp_path / "long.jsonl"
    exe = Path(sys.executable).with_name("mmexec")
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen([str(exe), "run", str(m), "--config", str(c), "--log", str(log)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            if log.exists() and '"skill":"drive_to"' in log.read_text():
                break
            time.sleep(0.05)
        else:
            pytest.fail("the run never started the drive")
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130, err
    assert "Traceback" not in err
    recs = read_log(log)
    names = [r["event"] for r in recs]
    assert "halt" in names and "skill_cancel" in names and "skill_stopped" in names
    assert names.index("halt") < names.index("skill_cancel") < names.index("skill_stopped")
    assert recs[-1]["event"] == "run_end" and recs[-1]["outcome"] == "interrupted"
    assert [r["outcome"] for r in recs if r["event"] == "request_end"] == ["interrupted"]
    assert "interrupted" in out


def test_show_prints_tree_and_writes_dot(run_cli, repo_root: Path, tmp_path: Path) -> None:
    dot = tmp_path / "tree.dot"
    res = run_cli("show", repo_root / "trees" / "demo_mock.yaml", "--dot", dot)
    assert res.rc == 0, res.err
    assert res.out.splitlines()[0].endswith("demo_fetch") and "go_to_shelf" in res.out and "pick_item" in res.out
    assert "    (R) pick_item  recovery, at most 2 recoveries\n        action: {-} sequence\n" in res.out
    assert "        --> grasp  close_gripper(expect=object)\n" in res.out and "    give_up: {-} sequence#3\n" in res.out
    text = dot.read_text()
    assert "digraph" in text and f"wrote {dot}" in res.out
    assert '"demo_fetch/pick_item" -> "demo_fetch/pick_item/sequence#3" [label="give_up"];' in text
    res = run_cli("show", repo_root / "trees" / "demo_mock.yaml", "--dot", tmp_path / "no" / "dir" / "x.dot")
    assert_input_error(res, "x.dot:1:1: cannot write")
