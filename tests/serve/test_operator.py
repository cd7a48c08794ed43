"""ask_operator: answered through the API, a --answers script and the terminal; its
timeout, its cancellation, and answers that do not fit."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from mmexec.config.yamlload import InputError
from mmexec.executive.serve.prompts import (
    PromptBoard,
    ScriptedAnswers,
    TerminalOperator,
    load_answers,
)
from mmexec.skills.base import FailureKind, SkillRun, SkillStatus
from mmexec.skills.operator import (
    OPERATOR_KEY,
    AnswerError,
    Prompt,
    ask_operator,
    parse_overlay,
    validate_answer,
)

ROOT = Path(__file__).resolve().parents[2]
SPEC = ask_operator.spec  # type: ignore[attr-defined]


def _script(tmp_path: Path, text: str) -> ScriptedAnswers:
    path = tmp_path / "answers.yaml"
    path.write_text(text)
    return ScriptedAnswers(load_answers(path), path)


def _events(ctx: Any, name: str) -> list[dict[str, Any]]:
    return [f for e, f in ctx.events if e == name]


# --------------------------------------------------------------------------- answers


@pytest.mark.parametrize(("kind", "value", "expected"), [
    ("confirm", True, True), ("confirm", "yes", True), ("confirm", "N", False),
    ("choose", "table", "table"), ("point", [3, 4.5], [3.0, 4.5]),
])
def test_validate_answer_converts(kind: str, value: Any, expected: Any) -> None:
    prompt = Prompt("p", kind, "q?", options=("shelf", "table") if kind == "choose" else (), image_size=(64, 48))
    assert validate_answer(prompt, value) == expected


@pytest.mark.parametrize(("kind", "value", "message"), [
    ("confirm", "maybe", "prompt p (confirm): expected yes or no (true/false), got 'maybe'"),
    ("choose", "floor", "prompt p (choose): expected one of ['shelf', 'table'], got 'floor'"),
    ("point", [1], "prompt p (point): expected [u, v], two finite pixel coordinates, got [1]"),
    ("point", [float("nan"), 1], "prompt p (point): expected [u, v], two finite pixel coordinates, got [nan, 1]"),
    ("point", [64, 10], "prompt p (point): [64, 10] is outside the 64x48 image"),
])
def test_validate_answer_refuses(kind: str, value: Any, message: str) -> None:
    prompt = Prompt("p", kind, "q?", options=("shelf", "table") if kind == "choose" else (), image_size=(64, 48))
    with pytest.raises(AnswerError) as e:
        validate_answer(prompt, value)
    assert str(e.value) == message


def test_overlay_shapes_are_checked() -> None:
    shapes = parse_overlay([{"shape": "box", "points": [[1, 2], [3, 4]], "label": "item"}])
    assert shapes[0].points == ((1.0, 2.0), (3.0, 4.0)) and shapes[0].label == "item"
    for bad, message in (([{"shape": "star", "points": [[1, 2]]}], "overlay[0]: shape must be one of"),
                         ([{"shape": "box", "points": [[1, 2]]}], "overlay[0]: a box takes 2 point(s), got 1"),
                         ([{"shape": "line", "points": [[1, 2]], "size": 3}], "overlay[0]: unknown key 'size'"),
                         (["box"], "overlay[0]: expected a mapping")):
        with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)").replace("[", r"\[")):
            parse_overlay(bad)


# --------------------------------------------------------------------------- the skill, scripted


def test_scripted_answers_in_order(tmp_path: Path, skill_ctx: Any, run_mock_skill: Any) -> None:
    skill_ctx.world[OPERATOR_KEY] = _script(tmp_path, "- yes\n- {answer: table, kind: choose}\n- [20, 30]\n")
    run = run_mock_skill(SPEC, {"kind": "confirm", "text": "go?"})
    assert run.status is SkillStatus.SUCCESS and run.outputs == {"answer": True, "source": "script"}
    run = run_mock_skill(SPEC, {"kind": "choose", "text": "where?", "options": ["shelf", "table"]})
    assert run.outputs["answer"] == "table"
    run = run_mock_skill(SPEC, {"kind": "point", "text": "click", "image": "camera",
                                "overlay": [{"shape": "point", "points": [[5, 5]]}]})
    assert run.outputs["answer"] == [20.0, 30.0]
    prompts = _events(skill_ctx, "operator_prompt")
    assert [p["kind"] for p in prompts] == ["confirm", "choose", "point"]
    assert prompts[2]["has_image"] is True and prompts[2]["image_size"] == [64, 48]
    assert [a["answer"] for a in _events(skill_ctx, "operator_answer")] == [True, "table", [20.0, 30.0]]


def test_scripted_answer_after_clock_seconds(tmp_path: Path, skill_ctx: Any, run_mock_skill: Any) -> None:
    skill_ctx.world[OPERATOR_KEY] = _script(tmp_path, "- {answer: no, after: 2.0}\n")
    t0 = skill_ctx.clock.now()
    run = run_mock_skill(SPEC, {"kind": "confirm", "text": "go?", "decline_fails": False})
    assert run.outputs["answer"] is False
    assert skill_ctx.clock.now() - t0 >= 2.0


def test_declined_confirmation_fails(tmp_path: Path, skill_ctx: Any, run_mock_skill: Any) -> None:
    skill_ctx.world[OPERATOR_KEY] = _script(tmp_path, "- no\n")
    run = run_mock_skill(SPEC, {"kind": "confirm", "text": "grasp?"})
    assert run.status is SkillStatus.FAILURE and run.failure.kind is FailureKind.EXECUTION
    assert run.failure.reason == "ask_operator: the operator declined: 'grasp?'"
    assert _events(skill_ctx, "operator_prompt_closed")[0]["reason"] == "declined"


def test_script_problems_fail_with_their_location(tmp_path: Path, skill_ctx: Any, run_mock_skill: Any) -> None:
    path = tmp_path / "answers.yaml"
    skill_ctx.world[OPERATOR_KEY] = _script(tmp_path, "- yes\n- {answer: shelf, kind: choose}\n- floor\n")
    run = run_mock_skill(SPEC, {"kind": "confirm", "text": "a?"})
    assert run.status is SkillStatus.SUCCESS
    run = run_mock_skill(SPEC, {"kind": "confirm", "text": "b?"})
    assert run.failure.kind is FailureKind.PRECONDITION
    assert run.failure.reason == (f"ask_operator: {path}:2:3: answer 2 is for a choose prompt, "
                                  "but prompt 2 ('b?') is a confirm")
    run = run_mock_skill(SPEC, {"kind": "choose", "text": "c?", "options": ["shelf", "table"]})
    assert run.failure.reason == (f"ask_operator: {path}:3:3: answer 3: prompt {_events(skill_ctx, 'operator_prompt')[-1]['id']}"
                                  " (choose): expected one of ['shelf', 'table'], got 'floor'")
    run = run_mock_skill(SPEC, {"kind": "confirm", "text": "d?"})
    assert run.failure.reason == f"ask_operator: {path}: no answer left for prompt 4 ('d?'): the file has 3"


def test_answers_file_errors_are_located(tmp_path: Path) -> None:
    path = tmp_path / "a.yaml"
    path.write_text("- {answer: yes, after: -1}\n- {kind: confirm}\n- {answer: 1, kind: nod, who: me}\n")
    with pytest.raises(InputError) as e:
        load_answers(path)
    lines = [str(p) for p in e.value.problems]
    assert f"{path}:1:24: answer 1: after: expected clock seconds >= 0, got -1" in lines
    assert f"{path}:2:3: answer 2: missing 'answer'" in lines
    assert any(line.startswith(f"{path}:3:") and "kind must be one of ['confirm', 'choose', 'point']" in line
               for line in lines)
    assert any("answer 3: unknown key 'who'" in line for line in lines)
    path.write_text("answer: yes\n")
    with pytest.raises(InputError, match="expected a YAML list of answers"):
        load_answers(path)


def test_nobody_to_answer_and_bad_prompts(skill_ctx: Any, run_mock_skill: Any) -> None:
    run = run_mock_skill(SPEC, {"kind": "confirm", "text": "go?"})
    assert run.failure.kind is FailureKind.PRECONDITION
    assert run.failure.reason.startswith("ask_operator: nobody can answer: run under 'mmexec serve'")
    skill_ctx.world[OPERATOR_KEY] = PromptBoard()
    for params, message in (({"kind": "point", "text": "x"}, "a point prompt needs an image (image: camera)"),
                            ({"kind": "choose", "text": "x"}, "a choose prompt needs 1..50 options, got 0"),
                            ({"kind": "confirm", "text": "x", "options": ["a"]}, "options are for choose prompts"),
                            ({"kind": "confirm", "text": "x", "timeout": -1.0}, "timeout must be a finite number")):
        run = run_mock_skill(SPEC, params)
        assert run.failure.kind is FailureKind.PRECONDITION and message in run.failure.reason


# --------------------------------------------------------------------------- timeout and cancel


def test_timeout_fails_with_a_clear_reason(skill_ctx: Any, run_mock_skill: Any) -> None:
    board = PromptBoard()
    skill_ctx.world[OPERATOR_KEY] = board
    run = run_mock_skill(SPEC, {"kind": "confirm", "text": "still there?", "timeout": 1.5})
    assert run.status is SkillStatus.FAILURE and run.failure.kind is FailureKind.TIMEOUT
    assert run.failure.reason == "ask_operator: no answer to 'still there?' within 1.5 s"
    assert board.open_prompts() == []
    assert _events(skill_ctx, "operator_prompt_closed")[0]["reason"] == "timeout"


def test_cancel_withdraws_the_prompt(skill_ctx: Any, mock_robot: Any) -> None:
    closed: list[dict[str, Any]] = []
    board = PromptBoard(notify=lambda kind, data: closed.append(data) if kind == "prompt_closed" else None)
    skill_ctx.world[OPERATOR_KEY] = board
    run = SkillRun(SPEC, skill_ctx, {"kind": "confirm", "text": "go?"})
    assert run.start() is SkillStatus.RUNNING
    for _ in range(3):
        mock_robot.spin(0.05)
        assert run.tick() is SkillStatus.RUNNING
    pid = board.open_prompts()[0].id
    assert run.cancel() is SkillStatus.CANCELLED
    assert board.open_prompts() == [] and closed == [{"id": pid, "reason": "cancelled"}]
    assert _events(skill_ctx, "operator_prompt_closed") == [{"node": "", "id": pid, "reason": "cancelled"}]
    with pytest.raises(LookupError, match="is not open"):
        board.answer(pid, True, "api")


# --------------------------------------------------------------------------- through the API


def test_answer_through_the_api(live: Any) -> None:
    svc = live("ask_confirm")
    c = svc.client
    rid = c.post("/api/requests", json={"item": 7}).json()["id"]
    prompt = svc.prompt()
    assert prompt["kind"] == "confirm" and prompt["text"] == "grasp item 7?" and prompt["node"] == "ask_confirm/confirm"
    assert prompt["has_image"] is False and prompt["image_url"] is None
    assert c.get("/api/status").json()["prompts"] == [prompt["id"]]
    bad = c.post(f"/api/prompts/{prompt['id']}/answer", json={"answer": "maybe"})
    assert bad.status_code == 422
    assert bad.json()["error"] == (f"POST /api/prompts/{prompt['id']}/answer: prompt {prompt['id']} (confirm): "
                                   "expected yes or no (true/false), got 'maybe'")
    assert c.post("/api/prompts/p0/answer", json={"answer": True}).status_code == 404
    assert c.post(f"/api/prompts/{prompt['id']}/answer", json={"answer": True, "source": "x"}).status_code == 422
    ok = c.post(f"/api/prompts/{prompt['id']}/answer", json={"answer": "yes", "source": "console"})
    assert ok.status_code == 200 and ok.json() == {"id": prompt["id"], "answer": True, "source": "console"}
    again = c.post(f"/api/prompts/{prompt['id']}/answer", json={"answer": False})
    assert again.status_code in (404, 409)
    assert svc.finished(rid)["state"] == "success"
    svc.close()
    answer = svc.records("operator_answer")[0]
    assert answer["answer"] is True and answer["source"] == "console" and answer["node"] == "ask_confirm/confirm"


def test_point_prompt_image_through_the_api(live: Any) -> None:
    svc = live("ask_point")
    c = svc.client
    with c.websocket_connect("/api/stream?topics=prompt") as ws:
        assert ws.receive_json()["type"] == "hello"
        rid = c.post("/api/requests", json={"item": 2}).json()["id"]
        msg = ws.receive_json()
    assert msg["type"] == "prompt" and msg["data"]["action"] == "prompt" and msg["data"]["kind"] == "point"
    pid = msg["data"]["id"]
    assert msg["data"]["image_url"] == f"/api/prompts/{pid}/image"
    assert msg["data"]["overlay"] == [{"shape": "box", "points": [[10.0, 10.0], [30.0, 30.0]], "label": "guess",
                                       "color": "#00ff00"}]
    img = c.get(msg["data"]["image_url"])
    assert img.status_code == 200 and img.headers["content-type"] == "image/jpeg" and img.content[:2] == b"\xff\xd8"
    outside = c.post(f"/api/prompts/{pid}/answer", json={"answer": [100, 10]})
    assert outside.status_code == 422 and "outside the 64x48 image" in outside.json()["error"]
    assert c.post(f"/api/prompts/{pid}/answer", json={"answer": [20, 21]}).status_code == 200
    assert svc.finished(rid)["state"] == "success"
    assert c.get(f"/api/prompts/{pid}/image").status_code == 404


def test_timeout_through_the_service(live: Any) -> None:
    svc = live("ask_confirm", params={"timeout": "0.5"})
    rid = svc.client.post("/api/requests", json={"item": 1}).json()["id"]
    end = svc.finished(rid)
    assert end["state"] == "failure" and end["reason"] == "ask_operator: no answer to 'grasp item 1?' within 0.5 s"
    svc.close()
    rec = svc.records("request_end")[0]
    assert rec["failure_kind"] == "timeout" and rec["failure_node"] == "ask_confirm/confirm"


# --------------------------------------------------------------------------- run --answers, the terminal


def _mmexec(*args: str, cwd: Path, stdin: Any = subprocess.DEVNULL) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-c", "import sys; from mmexec.executive.cli import main; sys.exit(main())",
                           *args], cwd=cwd, capture_output=True, text=True, stdin=stdin, timeout=300, check=False)


def test_run_with_an_answers_file(tmp_path: Path) -> None:
    mission = ROOT / "tests" / "serve" / "missions" / "ask_choose.yaml"
    (tmp_path / "answers.yaml").write_text("- shelf\n")
    r = _mmexec("run", str(mission), "--config", str(ROOT / "config" / "mock.yaml"), "--request", "item=4",
                "--answers", "answers.yaml", "--log", "run.jsonl", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    (tmp_path / "answers.yaml").write_text("- {answer: shelf, after: nope}\n")
    r = _mmexec("run", str(mission), "--config", str(ROOT / "config" / "mock.yaml"), "--request", "item=4",
                "--answers", "answers.yaml", "--log", "run2.jsonl", cwd=tmp_path)
    assert r.returncode == 2
    assert r.stderr == "answers.yaml:1:26: answer 1: after: expected clock seconds >= 0, got 'nope'\n"
    assert not (tmp_path / "run2.jsonl").exists()


def test_run_without_anyone_to_answer(tmp_path: Path) -> None:
    mission = ROOT / "tests" / "serve" / "missions" / "ask_choose.yaml"
    r = _mmexec("run", str(mission), "--config", str(ROOT / "config" / "mock.yaml"), "--request", "item=4",
                "--log", "run.jsonl", cwd=tmp_path)
    assert r.returncode == 1
    assert "nobody can answer" in r.stdout


def test_terminal_operator_reads_without_blocking(tmp_path: Path) -> None:
    import io

    read_fd, write_fd = os.pipe()
    out = io.StringIO()
    term = TerminalOperator(read_fd, out, image_dir=tmp_path)
    prompt = Prompt("p9", "choose", "where?", options=("shelf", "table"), image=b"\xff\xd8jpeg", image_size=(4, 4))
    term.ask(prompt)
    assert "operator: where?" in out.getvalue() and "2) table" in out.getvalue()
    assert (tmp_path / "p9.jpg").read_bytes() == b"\xff\xd8jpeg"
    assert term.poll("p9", 0.0) is None  # nothing typed: returns at once
    os.write(write_fd, b"floor\n2")
    assert term.poll("p9", 0.0) is None  # a wrong answer is explained, the half line waits
    assert "expected one of ['shelf', 'table'], got 'floor'" in out.getvalue()
    os.write(write_fd, b"\n")
    answer = term.poll("p9", 0.0)
    assert answer is not None and answer.value == "table" and answer.source == "terminal"
    term.close("p9", "answered")
    confirm = Prompt("p10", "confirm", "ok?")
    term.ask(confirm)
    os.close(write_fd)
    with pytest.raises(AnswerError, match="the terminal's input ended before prompt p10 was answered"):
        term.poll("p10", 0.0)
    os.close(read_fd)


def test_run_asks_on_the_terminal(tmp_path: Path) -> None:
    """``mmexec run`` with a terminal on stdin: the question on stderr, the typed answer
    read between ticks (a wrong one explained), the request done."""
    import pty
    import select
    import time

    master, slave = pty.openpty()
    exe = Path(sys.executable).with_name("mmexec")
    proc = subprocess.Popen([str(exe), "run", str(ROOT / "tests" / "serve" / "missions" / "ask_confirm.yaml"),
                             "--config", str(ROOT / "config" / "mock.yaml"), "--request", "item=5", "--log",
                             "run.jsonl"], cwd=tmp_path, stdin=slave, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    os.close(slave)
    err = b""
    try:
        assert proc.stderr is not None
        deadline = time.monotonic() + 120
        while b"answer y or n" not in err:
            ready, _, _ = select.select([proc.stderr], [], [], max(0.0, deadline - time.monotonic()))
            assert ready, f"no prompt on stderr: {err!r}"
            chunk = os.read(proc.stderr.fileno(), 4096)
            assert chunk, f"exited before the prompt: {err!r}"
            err += chunk
        os.write(master, b"perhaps\n")
        while b"got 'perhaps'" not in err:
            ready, _, _ = select.select([proc.stderr], [], [], max(0.0, deadline - time.monotonic()))
            assert ready, f"no explanation on stderr: {err!r}"
            err += os.read(proc.stderr.fileno(), 4096)
        os.write(master, b"y\n")
        assert proc.wait(120) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        os.close(master)
        for stream in (proc.stdout, proc.stderr):
            if stream is not None:
                stream.close()
    assert b"operator: grasp item 5?" in err
    from mmexec.executive.eventlog import read_log

    answer = [r for r in read_log(tmp_path / "run.jsonl") if r["event"] == "operator_answer"]
    assert [(a["answer"], a["source"]) for a in answer] == [(True, "terminal")]
