"""``mmexec log replay`` / ``log summary`` on hand-made event logs: every event under the
frame of its own clock time, ``--request N`` beyond the log, and logs carrying odd values.

The records follow the runner's order within a tick (an event is written before the
node_status changes it causes, e.g. ``skill_failure`` at t = 2.0 before the leaf's
FAILURE at 2.0), as a real log of tests/executive/test_cli_commands.py shows."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from mmexec.executive.logtools import (
    Frame,
    NoSuchRequest,
    render_frame,
    replay_frames,
    request_count,
    summary,
)

NODES = ["m", "m/grasp", "m/go_home"]


def status(seq: int, t: float, path: str, new: str) -> dict[str, Any]:
    return {"event": "node_status", "seq": seq, "t": t, "path": path, "old": "?", "new": new}


def request_log(index: int = 1, of: int = 1, t0: float = 0.0) -> list[dict[str, Any]]:
    """One request: a report at its start, grasp RUNNING at t0, a skill_failure at t0 + 2
    (before the leaf's FAILURE at the same instant), go_home from t0 + 2 to t0 + 5, and
    request_end at t0 + 5."""
    return [
        {"event": "request_start", "seq": 1, "t": t0, "index": index, "of": of, "request": {"item": index},
         "nodes": NODES},
        {"event": "report", "seq": 2, "t": t0, "node": "m", "message": f"fetching {index}"},
        status(3, t0, "m", "RUNNING"),
        status(4, t0, "m/grasp", "RUNNING"),
        {"event": "skill_failure", "seq": 5, "t": t0 + 2.0, "node": "m/grasp", "skill": "close_gripper",
         "kind": "postcondition", "reason": "closed on nothing"},
        status(6, t0 + 2.0, "m/grasp", "FAILURE"),
        status(7, t0 + 2.0, "m/go_home", "RUNNING"),
        {"event": "report", "seq": 8, "t": t0 + 5.0, "node": "m/go_home", "message": "home"},
        status(9, t0 + 5.0, "m/go_home", "SUCCESS"),
        status(10, t0 + 5.0, "m", "SUCCESS"),
        {"event": "request_end", "seq": 11, "t": t0 + 5.0, "index": index, "outcome": "success"},
    ]


def by_time(frames: list[Frame]) -> dict[float, Frame]:
    times = [f.t for f in frames]
    assert len(set(times)) == len(times), f"two frames at one instant: {times}"
    return {f.t: f for f in frames}


def test_every_event_is_shown_under_the_frame_of_its_own_time() -> None:
    frames = by_time(list(replay_frames(request_log())))
    assert sorted(frames) == [0.0, 2.0, 5.0]
    # the failure at 2.0 used to be appended to the frame at 0.0 (written before the
    # FAILURE status at 2.0, it reached the frame still open); the report at the
    # request's start (before any node_status) used to be dropped
    assert frames[0.0].events == ["report m fetching 1"]
    assert frames[2.0].events == ["skill_failure m/grasp closed on nothing"]
    assert frames[5.0].events == ["report m/go_home home", "request_end  success"]
    assert frames[2.0].status == {"m": "RUNNING", "m/grasp": "FAILURE", "m/go_home": "RUNNING"}
    assert frames[2.0].changed == {"m/grasp", "m/go_home"}


def test_an_event_at_an_instant_without_status_changes_gets_its_own_frame() -> None:
    records = request_log()
    records.insert(4, {"event": "recovery_attempt", "seq": 40, "t": 1.0, "node": "m", "attempt": 1,
                       "reason": "slipped"})
    frames = by_time(list(replay_frames(records)))
    assert sorted(frames) == [0.0, 1.0, 2.0, 5.0]
    one = frames[1.0]
    assert one.events == ["recovery_attempt m slipped"] and one.changed == set()
    assert one.status == {"m": "RUNNING", "m/grasp": "RUNNING", "m/go_home": "INVALID"}
    assert "<<" not in render_frame(one) and "  ! recovery_attempt m slipped" in render_frame(one)


def test_request_filter_keeps_each_requests_own_frames() -> None:
    records = request_log(1, 2) + request_log(2, 2, t0=10.0)
    assert request_count(records) == 2
    second = list(replay_frames(records, request=2))
    assert [(f.index, f.t) for f in second] == [(2, 10.0), (2, 12.0), (2, 15.0)]
    assert second[0].events == ["report m fetching 2"]
    assert [f.index for f in replay_frames(records)] == [1, 1, 1, 2, 2, 2]


@pytest.mark.parametrize(("number", "held", "message"), [
    (3, 2, "no request 3: the log has 2 requests"),
    (0, 2, "no request 0: the log has 2 requests"),
    (-1, 1, "no request -1: the log has 1 request"),
    (1, 0, "no request 1: the log has no requests"),
])
def test_a_request_the_log_does_not_hold_is_refused_before_iteration(number: int, held: int, message: str) -> None:
    records = [r for i in range(held) for r in request_log(i + 1, held, t0=10.0 * i)]
    with pytest.raises(NoSuchRequest) as info:
        replay_frames(records, request=number)  # raised by the call, not by the first next()
    assert str(info.value) == message


def test_records_with_odd_values_replay_and_summarise() -> None:
    """A log written by hand or by another tool: strings where numbers belong, a NaN that
    to_jsonable wrote as a string, a node list that is not a list, an unhashable reason."""
    records = [
        {"event": "run_start", "seq": 0, "requests": 1},
        {"event": "request_start", "seq": 1, "index": "one", "of": None, "nodes": 7, "t": "soon"},
        status(2, 1.0, "m", "RUNNING"),
        {"event": "node_status", "seq": 3, "t": "nan", "path": "m", "new": "FAILURE"},
        {"event": "halt", "seq": 4, "reason": "interrupt"},
        {"event": "request_end", "seq": 5, "t": True, "index": 1, "outcome": ["failure"], "duration": "long",
         "reason": {"why": "list"}},
        {"event": "mission_reload", "seq": 6, "t": 2.0, "ok": False, "problems": "not a list"},
    ]
    frames = list(replay_frames(records))
    # a record without a usable t belongs to the instant before it
    assert [(f.index, f.t) for f in frames] == [(1, 1.0)]
    assert frames[0].status == {"m": "FAILURE"}
    assert frames[0].events == ["halt  interrupt", "request_end  {'why': 'list'}"]
    text = summary(records)
    assert "request 1/1 (-): ['failure'] after ?" in text
    assert "mission reload at 2.0 s: rejected: " in text


def test_a_served_log_numbers_requests_without_a_total() -> None:
    """``mmexec serve`` takes requests one by one: its run_start says ``requests: 0`` and
    each request_start ``of: 0``; the summary and the replay say "request 2", not "2/0"."""
    records = [{"event": "run_start", "seq": 0, "requests": 0}]
    records += [r for i in range(2) for r in request_log(i + 1, 0, t0=10.0 * i)]
    text = summary(records)
    assert "request 2 (item=2): success after" in text, text
    assert "/0" not in text
    assert "requests: 2 served, 2 succeeded" in text, text
    frames = list(replay_frames(records, request=2))
    assert render_frame(frames[0]).startswith("── request 2  t = 10.00 s ──")
    # a run with a fixed number of requests keeps "k/n"
    fixed = [{"event": "run_start", "seq": 0, "requests": 2}] + records[1:]
    assert "request 2/2 (" in summary(fixed)
    assert "requests: 2 served of 2, 2 succeeded" in summary(fixed)


def test_cli_request_beyond_the_log_exits_2_in_one_line(run_cli, tmp_path: Path) -> None:
    log = tmp_path / "two.jsonl"
    log.write_text("".join(json.dumps(r) + "\n" for r in request_log(1, 2) + request_log(2, 2, t0=10.0)))
    for n in ("3", "0"):
        res = run_cli("log", "replay", log, "--request", n)
        assert res.rc == 2 and res.out == ""
        assert res.err.splitlines() == [f"--request: no request {n}: the log has 2 requests ({log})"]
    res = run_cli("log", "replay", log, "--request", "2")
    assert res.rc == 0 and res.out.count("── request 2/2") == 3


def test_cli_log_path_through_a_file_is_one_line(run_cli, tmp_path: Path) -> None:
    plain = tmp_path / "plain.jsonl"
    plain.write_text("")
    for action in ("summary", "replay"):
        res = run_cli("log", action, plain / "x.jsonl")
        assert res.rc == 2 and res.out == ""
        assert res.err.splitlines() == [f"{plain / 'x.jsonl'}:1:1: cannot read: Not a directory"]
