"""`mmexec demo`: the fetch mission on the headless LoCoBot sim for items 3 and 5, a
per-request table, the event log and a video in --out; `demo --mock` the small demo."""

from __future__ import annotations

from pathlib import Path

import imageio.v2 as imageio

from mmexec.executive.cli import demo_table
from mmexec.executive.eventlog import read_log
from mmexec.executive.runner import RequestResult


def test_demo_serves_two_fetches_and_writes_log_and_video(run_cli, tmp_path: Path) -> None:
    out = tmp_path / "demo"
    res = run_cli("demo", "--out", out)
    assert res.rc == 0, res.out + res.err
    lines = res.out.splitlines()
    head = next(i for i, ln in enumerate(lines) if ln.startswith("request  "))
    assert lines[head].split() == ["request", "result", "clock", "s", "recoveries", "failure", "reason"]
    rows = [ln.split() for ln in lines[head + 2:head + 4]]
    assert [r[:3] for r in rows] == [["1", "(item=3)", "success"], ["2", "(item=5)", "success"]]
    assert all(float(r[3]) > 0 and r[5] == "-" for r in rows)
    records = read_log(out / "events.jsonl")
    ends = [r for r in records if r["event"] == "request_end"]
    assert [(e["request"], e["outcome"]) for e in ends] == [({"item": 3}, "success"), ({"item": 5}, "success")]
    assert [float(r[3]) for r in rows] == [round(e["duration"], 1) for e in ends]
    assert records[-1]["event"] == "run_end" and records[-1]["outcome"] == "ok"
    reader = imageio.get_reader(str(out / "demo.mp4"))
    try:
        frames = reader.count_frames()
        first = reader.get_data(0)
    finally:
        reader.close()
    # one frame per 0.5 s of clock time over both requests
    assert frames >= int(sum(e["duration"] for e in ends) / 0.5) - 2
    assert first.shape[:2] == (240, 320)
    assert f"video: {out / 'demo.mp4'}" in res.out


def test_demo_mock_is_the_small_demo(run_cli, tmp_path: Path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    res = run_cli("demo", "--mock")
    assert res.rc == 0, res.err
    assert "request 1/2 (item=1): success" in res.out and "1 recovery" in res.out
    assert not (tmp_path / "out").exists()


def test_demo_table_lists_failures_with_their_reason() -> None:
    rows = [RequestResult(1, {"item": 3}, "success", 51.04),
            RequestResult(2, {"item": 6}, "failure", 120.0, recoveries=2, reason="pre-grasp: no collision-free IK")]
    table = demo_table(rows).splitlines()
    assert len(table) == 4
    assert table[2].split() == ["1", "(item=3)", "success", "51.0", "0", "-"]
    assert table[3].split()[:5] == ["2", "(item=6)", "failure", "120.0", "2"]
    assert table[3].endswith("pre-grasp: no collision-free IK")


def test_demo_out_that_cannot_be_created_is_a_located_error(run_cli, tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("x")
    res = run_cli("demo", "--out", blocker / "sub")
    assert res.rc == 2 and res.err.startswith(f"{blocker / 'sub'}:1:1: --out: cannot create the folder")
