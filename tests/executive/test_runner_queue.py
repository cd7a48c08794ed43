"""Runner: request queue, outcomes and exit codes, timeouts, interrupts, --watch, log content."""

from __future__ import annotations

import io
import itertools
from pathlib import Path

import pytest

from mmexec.config.yamlload import InputError, Mark
from mmexec.executive.eventlog import read_log
from mmexec.executive.runner import Progress, Request, Runner, RunOptions
from mmexec.skills.base import REGISTRY, skill

CONFIG = """\
backend: mock
rate_hz: 20
mock:
  arm: {fail_moves: [1], fail_reason: "elbow overload", stop_time: 0.2}
profile:
  named_poses:
    ready: [0.0, -0.5, 0.6, 0.0, 0.5, 0.0]
"""

MISSION = """\
mission: arm_once
requests:
  item: {type: int}
tree:
  sequence:
    - skill: report
      params: {message: "item {request.item}"}
    - skill: move_arm
      params: {pose: ready}
"""


def make(tmp_path: Path, mission: str = MISSION, config: str = CONFIG) -> tuple[Path, Path]:
    m, c = tmp_path / "mission.yaml", tmp_path / "config.yaml"
    m.write_text(mission)
    c.write_text(config)
    return m, c


def reqs(*items: int) -> list[Request]:
    return [Request({"item": str(i)}, Mark("--request", n, 1)) for n, i in enumerate(items, start=1)]


def runner_for(tmp_path: Path, mission: Path, config: Path, requests: list[Request], **kw) -> Runner:
    opts = RunOptions(mission=mission, config=config, requests=requests, log_path=tmp_path / "run.jsonl", **kw)
    out, err = io.StringIO(), io.StringIO()
    r = Runner(opts, out=out, err=err, progress=Progress(out, enabled=False), registry=kw.pop("registry", REGISTRY))
    r.prepare()
    return r


def events(path: Path, name: str) -> list[dict]:
    return [r for r in read_log(path) if r["event"] == name]


def test_failed_request_does_not_stop_the_queue(tmp_path: Path) -> None:
    m, c = make(tmp_path)
    r = runner_for(tmp_path, m, c, reqs(7, 8, 9))
    assert r.run() == 1
    assert [x.outcome for x in r.results] == ["failure", "success", "success"]
    first = r.results[0]
    assert "elbow overload" in first.reason and first.failure_kind == "execution"
    assert first.failure_node.endswith("move_arm")
    log = tmp_path / "run.jsonl"
    ends = events(log, "request_end")
    assert [e["outcome"] for e in ends] == ["failure", "success", "success"]
    assert [e["request"] for e in ends] == [{"item": 7}, {"item": 8}, {"item": 9}]
    assert "elbow overload" in ends[0]["reason"]
    run_end = events(log, "run_end")[0]
    assert run_end["outcome"] == "failed" and run_end["succeeded"] == 2 and run_end["failed"] == 1
    assert run_end["exit_code"] == 1
    out = r.out.getvalue()
    assert "request 1/3 (item=7): failure" in out and "2/3 requests succeeded, 1 failed" in out
    assert r.robot.closed


def test_all_succeed_exit_zero_and_log_identity(tmp_path: Path) -> None:
    m, c = make(tmp_path, config=CONFIG.replace("fail_moves: [1]", "fail_moves: []"))
    r = runner_for(tmp_path, m, c, reqs(1, 2), seed=5, argv=["run", "x"])
    assert r.run() == 0
    recs = read_log(tmp_path / "run.jsonl")
    start = recs[0]
    assert start["event"] == "run_start"
    assert start["mission_sha256"] == r.mission.sha256 and len(start["config_sha256"]) == 64
    assert start["backend"] == "mock" and start["seed"] == 5 and start["argv"] == ["run", "x"]
    assert {"python", "mmexec", "py_trees"} <= set(start["versions"])
    assert [x["seq"] for x in recs] == list(range(len(recs)))
    rs = events(tmp_path / "run.jsonl", "request_start")[0]
    assert rs["nodes"][0] == "arm_once" and "arm_once/move_arm" in rs["nodes"]
    ns = events(tmp_path / "run.jsonl", "node_status")
    assert {"path", "old", "new", "t"} <= set(ns[0])
    assert any(x["path"] == "arm_once/move_arm" and x["new"] == "SUCCESS" for x in ns)
    # clock time advances through the run, one spin of 1/rate_hz between ticks
    ts = [x["t"] for x in ns]
    assert ts == sorted(ts) and ts[-1] > 0.1
    assert [e["message"] for e in events(tmp_path / "run.jsonl", "report")] == ["item 1", "item 2"]
    assert "  item 1\n" in r.out.getvalue()


def test_rate_override_changes_clock_step(tmp_path: Path) -> None:
    m, c = make(tmp_path, mission=MISSION.replace("skill: move_arm\n      params: {pose: ready}", "wait: 1.0"))
    r = runner_for(tmp_path, m, c, reqs(1), rate_hz=4.0)
    assert r.run() == 0
    ns = events(tmp_path / "run.jsonl", "node_status")
    ts = sorted({x["t"] for x in ns})
    assert all(abs(b - a - 0.25) < 1e-9 or b - a > 0.25 for a, b in itertools.pairwise(ts))
    assert r.results[0].duration == pytest.approx(1.0, abs=0.26)


def test_request_timeout_halts_and_cancels_the_skill(tmp_path: Path) -> None:
    mission = MISSION.replace("skill: move_arm\n      params: {pose: ready}",
                              "skill: drive_to\n      params: {x: 100.0, y: 0.0}")
    m, c = make(tmp_path, mission=mission)
    r = runner_for(tmp_path, m, c, reqs(1, 2), request_timeout=2.0)
    assert r.run() == 1
    assert [x.outcome for x in r.results] == ["timeout", "timeout"]
    log = tmp_path / "run.jsonl"
    assert len(events(log, "skill_cancel")) == 2
    stopped = events(log, "skill_stopped")
    assert len(stopped) == 2 and all(s["ticks"] > 1 for s in stopped)  # braking took several ticks
    assert abs(r.robot.base.state().v) < 1e-3


def test_interrupt_halts_tree_and_exits_130(tmp_path: Path) -> None:
    mission = MISSION.replace("skill: move_arm\n      params: {pose: ready}",
                              "skill: drive_to\n      params: {x: 100.0, y: 0.0}")
    m, c = make(tmp_path, mission=mission)
    r = runner_for(tmp_path, m, c, reqs(1, 2))
    pressed = []

    def press_ctrl_c(record: dict) -> None:
        if record["event"] == "skill_start" and record["skill"] == "drive_to" and not pressed:
            pressed.append(record["t"])
            r.interrupt()

    r.add_log_listener(press_ctrl_c)
    assert r.run() == 130
    log = tmp_path / "run.jsonl"
    assert [e["reason"] for e in events(log, "halt")] == ["interrupt"]
    assert len(events(log, "skill_cancel")) == 1 and len(events(log, "skill_stopped")) == 1
    assert [e["outcome"] for e in events(log, "request_end")] == ["interrupted"]
    run_end = events(log, "run_end")[0]
    assert run_end["outcome"] == "interrupted" and run_end["exit_code"] == 130 and run_end["served"] == 1
    assert r.robot.closed and abs(r.robot.base.state().v) < 1e-3


def test_second_interrupt_abandons_the_stop(tmp_path: Path) -> None:
    mission = MISSION.replace("skill: move_arm\n      params: {pose: ready}",
                              "skill: drive_to\n      params: {x: 100.0, y: 0.0}")
    m, c = make(tmp_path, mission=mission)
    r = runner_for(tmp_path, m, c, reqs(1))

    def press_twice(record: dict) -> None:
        if record["event"] == "skill_start" and record["skill"] == "drive_to":
            r.interrupt()
        if record["event"] == "halt":
            r.interrupt()

    r.add_log_listener(press_twice)
    assert r.run() == 130
    log = tmp_path / "run.jsonl"
    assert [e["reason"] for e in events(log, "halt_abandoned")] == ["second interrupt"]
    assert r.robot.safe_stops >= 1 and r.robot.closed
    assert events(log, "run_end")[0]["outcome"] == "interrupted"


def test_exception_in_skill_ends_request_not_queue(tmp_path: Path) -> None:
    reg = REGISTRY.copy()

    @skill("explode_t", registry=reg)
    def explode(ctx):
        yield
        raise RuntimeError("kaboom")

    mission = MISSION.replace("skill: move_arm\n      params: {pose: ready}", "skill: explode_t")
    m, c = make(tmp_path, mission=mission)
    opts = RunOptions(mission=m, config=c, requests=reqs(1, 2), log_path=tmp_path / "run.jsonl")
    out = io.StringIO()
    r = Runner(opts, out=out, err=io.StringIO(), progress=Progress(out, enabled=False), registry=reg)
    r.prepare()
    assert r.run() == 1
    assert [x.outcome for x in r.results] == ["error", "error"]
    assert "kaboom" in r.results[0].reason and "explode_t" in r.results[0].reason
    assert r.robot.safe_stops >= 2


def test_bad_requests_are_input_errors_with_origin(tmp_path: Path) -> None:
    m, c = make(tmp_path)
    opts = RunOptions(mission=m, config=c, requests=[Request({"item": "x"}, Mark("req.yaml", 3, 3)),
                                                     Request({"itme": "1"}, Mark("req.yaml", 4, 3))])
    with pytest.raises(InputError) as ei:
        Runner(opts, out=io.StringIO()).prepare()
    lines = str(ei.value).splitlines()
    assert lines[0].startswith("req.yaml:3:3: request 1: ") and "'item'" in lines[0]
    assert lines[1].startswith("req.yaml:4:3: request 2: ") and "did you mean 'item'" in lines[1]


def test_watch_reloads_between_requests(tmp_path: Path) -> None:
    m, c = make(tmp_path, config=CONFIG.replace("fail_moves: [1]", "fail_moves: []"))
    r = runner_for(tmp_path, m, c, reqs(1, 2, 3), watch=True)

    def edit(record: dict) -> None:
        if record["event"] == "request_start" and record["index"] == 1:
            # edited while request 1 runs: must not affect it, only request 2
            m.write_text(MISSION.replace('"item {request.item}"', '"v2 item {request.item}"'))
        if record["event"] == "request_start" and record["index"] == 2:
            m.write_text(MISSION.replace("skill: report", "skill: reprot"))

    r.add_log_listener(edit)
    assert r.run() == 0
    log = tmp_path / "run.jsonl"
    assert [e["message"] for e in events(log, "report")] == ["item 1", "v2 item 2", "v2 item 3"]
    reloads = events(log, "mission_reload")
    assert [x["ok"] for x in reloads] == [True, False]
    assert "unknown skill 'reprot'" in reloads[1]["problems"][0]
    err = r.err.getvalue().splitlines()
    assert "changed but has errors; still running the previous version" in err[0]
    assert err[1].startswith(f"{m}:") and "did you mean 'report'" in err[1]
    assert "reloaded" in r.out.getvalue()


def test_progress_line_on_a_terminal(tmp_path: Path) -> None:
    m, c = make(tmp_path, config=CONFIG.replace("fail_moves: [1]", "fail_moves: []"))
    opts = RunOptions(mission=m, config=c, requests=reqs(1), log_path=tmp_path / "run.jsonl")
    screen = io.StringIO()
    r = Runner(opts, out=io.StringIO(), err=io.StringIO(), progress=Progress(screen, enabled=True, interval=0.0))
    r.prepare()
    assert r.run() == 0
    text = screen.getvalue()
    assert "\r[1/1]" in text and "arm_once/move_arm" in text and "\x1b[K" in text
    assert text.endswith("\r\x1b[K")  # cleared at the end


@pytest.mark.parametrize("exc,code", [(InputError.at(Mark("config.yaml", 3, 5), "robot.base: no such port"), 2),
                                      (RuntimeError("driver crashed"), 1)])
def test_run_end_records_the_exit_code_the_command_returns(tmp_path: Path, exc, code) -> None:
    """A backend that fails to start: the log's run_end carries the status mmexec exits
    with (2 for bad input such as a missing port, 1 otherwise), and the error propagates."""
    m, c = make(tmp_path)
    r = runner_for(tmp_path, m, c, reqs(7))

    def factory(_loaded):
        raise exc

    r.robot_factory = factory
    with pytest.raises((InputError, RuntimeError)):
        r.run()
    run_end = events(tmp_path / "run.jsonl", "run_end")[0]
    assert run_end["outcome"] == "error" and run_end["exit_code"] == code


@pytest.mark.parametrize("rate", [0.5, 1001.0, float("nan"), float("inf")])
def test_prepare_refuses_a_tick_rate_the_config_would_refuse(tmp_path: Path, rate: float) -> None:
    # a library caller (campaign, serve) gets the same bounds as the command line and config
    m, c = make(tmp_path)
    with pytest.raises(InputError, match=r"--rate.*expected a tick rate in \[1, 1000\] Hz"):
        runner_for(tmp_path, m, c, reqs(1), rate_hz=rate)
