"""The service's HTTP + WebSocket API on the mock backend: every endpoint, its 4xx errors,
the token, the body cap, CORS, the streams, and the event log as the record."""

from __future__ import annotations

import base64
import json
from pathlib import Path
from typing import Any

import pytest
from starlette.websockets import WebSocketDisconnect

from mmexec.executive.compiler import load_mission
from mmexec.executive.serve.app import create_app
from mmexec.executive.serve.service import TOPICS, Service
from mmexec.executive.serve.settings import ServeSettings


def test_index_status_and_openapi(live: Any) -> None:
    svc = live()
    c = svc.client
    assert c.get("/").json()["api"] == "/api/status"
    st = c.get("/api/status").json()
    assert st["state"] == "idle" and st["mission"] == "quick" and st["backend"] == "mock"
    assert st["queued"] == 0 and st["current"] is None and st["log"] == str(svc.log_path)
    paths = c.get("/openapi.json").json()["paths"]
    for path in ("/api/status", "/api/requests", "/api/requests/{rid}", "/api/halt", "/api/pause", "/api/resume",
                 "/api/stop", "/api/prompts", "/api/prompts/{pid}/image", "/api/prompts/{pid}/answer"):
        assert path in paths, path
    assert set(paths["/api/requests/{rid}"]) == {"get", "delete"}
    assert c.get("/docs").status_code == 200


def test_submit_and_serve_writes_the_log_as_run_does(live: Any) -> None:
    svc = live()
    r = svc.client.post("/api/requests", json={"item": 3})
    assert r.status_code == 202
    body = r.json()
    assert body["request"] == {"item": 3} and body["state"] in ("queued", "running", "success")
    done = svc.finished(body["id"])
    assert done["state"] == "success"
    assert svc.client.get(f"/api/requests/{body['id']}").json()["state"] == "success"
    assert svc.close() == 0
    events = [r["event"] for r in svc.records()]
    assert events[0] == "run_start" and events[-1] == "run_end"
    assert events.index("request_queued") < events.index("request_start") < events.index("request_end")
    assert "node_status" in events and "report" in events
    end = svc.records("request_end")[0]
    assert end["id"] == body["id"] and end["index"] == 1 and end["outcome"] == "success"
    assert svc.records("request_start")[0]["id"] == body["id"]
    assert svc.records("run_end")[0]["outcome"] == "stopped"
    assert "request 1 (item=3): success" in svc.out.getvalue()


@pytest.mark.parametrize(("body", "message"), [
    ({"itme": 3}, "POST /api/requests: request: unknown field 'itme'; did you mean 'item'? (mission quick takes: item)"),
    ({}, "POST /api/requests: request: missing field 'item' (int)"),
    ({"item": "seven"}, "POST /api/requests: request field 'item': expected int, got 'seven'"),
    ({"item": [1]}, "POST /api/requests: request field 'item': expected a scalar value"),
    ([1, 2], "POST /api/requests: body: Input should be a valid dictionary"),
])
def test_submit_bad_fields_is_422_with_the_run_message(live: Any, body: Any, message: str) -> None:
    svc = live()
    r = svc.client.post("/api/requests", json=body)
    assert r.status_code == 422
    assert r.json() == {"error": message}


def test_submit_messages_match_the_command_line(live: Any, missions: Path) -> None:
    """The API's message after its location is the one ``--request`` prints after its own."""
    svc = live()
    mission = load_mission(missions / "quick.yaml")
    for fields in ({"itme": "3"}, {"item": "seven"}):
        with pytest.raises(ValueError, match=r".*") as e:
            mission.validate_request(fields)
        r = svc.client.post("/api/requests", json=fields)
        assert r.json()["error"] == f"POST /api/requests: {e.value}"


def test_submit_non_json_and_nan(live: Any) -> None:
    svc = live()
    r = svc.client.post("/api/requests", content=b"{not json", headers={"content-type": "application/json"})
    assert r.status_code == 422 and r.json()["error"].startswith("POST /api/requests: body")
    r = svc.client.post("/api/requests", content=b'{"item": NaN}', headers={"content-type": "application/json"})
    assert r.status_code == 422 and "item" in r.json()["error"]


def test_queue_pause_cancel_resume(live: Any) -> None:
    svc = live()
    c = svc.client
    assert c.post("/api/pause").json()["state"] == "paused"
    ids = [c.post("/api/requests", json={"item": i}).json()["id"] for i in range(3)]
    listed = c.get("/api/requests").json()
    assert [q["id"] for q in listed["queued"]] == ids and listed["current"] is None
    r = c.delete(f"/api/requests/{ids[1]}")
    assert r.status_code == 200 and r.json()["state"] == "dropped"
    again = c.delete(f"/api/requests/{ids[1]}")
    assert again.status_code == 409 and again.json()["error"] == f"request {ids[1]}: already ended (dropped)"
    missing = c.delete("/api/requests/999")
    assert missing.status_code == 404 and missing.json()["error"] == "request 999: no such request"
    assert c.get("/api/requests/999").status_code == 404
    assert c.get("/api/requests/x").status_code == 422
    assert c.get("/api/status").json()["queued"] == 2
    assert c.post("/api/resume").json()["paused"] is False
    assert svc.finished(ids[2])["state"] == "success"
    assert svc.close() == 0
    assert [r["id"] for r in svc.records("request_queued")] == ids
    dropped = svc.records("request_dropped")
    assert [(d["id"], d["reason"]) for d in dropped] == [(ids[1], "cancelled through the API")]
    assert [(r["index"], r["id"]) for r in svc.records("request_end")] == [(1, ids[0]), (2, ids[2])]
    assert [r["event"] for r in svc.records() if r["event"] in ("paused", "resumed")] == ["paused", "resumed"]


def test_halt_the_running_request_and_the_queue_goes_on(live: Any) -> None:
    svc = live("ask_confirm")
    c = svc.client
    assert c.post("/api/halt").status_code == 409
    first = c.post("/api/requests", json={"item": 1}).json()["id"]
    second = c.post("/api/requests", json={"item": 2}).json()["id"]
    prompt = svc.prompt()
    assert c.get("/api/status").json()["current"]["id"] == first
    r = c.delete(f"/api/requests/{first}")
    assert r.status_code == 202 and r.json()["state"] == "running"
    end = svc.finished(first)
    assert end["state"] == "cancelled" and end["reason"] == "cancelled through the API"
    svc.wait(lambda: svc.client.get("/api/status").json()["current"], "the second request")
    assert c.post("/api/halt").status_code == 202
    assert svc.finished(second)["state"] == "cancelled"
    assert svc.close() == 0
    halts = svc.records("halt")
    assert [(h["reason"], h["index"]) for h in halts] == [("cancel", first), ("cancel", second)]
    closed = svc.records("operator_prompt_closed")
    assert closed[0]["id"] == prompt["id"] and closed[0]["reason"] == "cancelled"
    assert [e["outcome"] for e in svc.records("request_end")] == ["cancelled", "cancelled"]
    assert svc.records("skill_cancel")


def test_stop_drops_the_queue_and_refuses_new_requests(live: Any) -> None:
    svc = live("ask_confirm")
    c = svc.client
    first = c.post("/api/requests", json={"item": 1}).json()["id"]
    queued = c.post("/api/requests", json={"item": 2}).json()["id"]
    svc.prompt()
    r = c.post("/api/stop")
    assert r.status_code == 202 and r.json()["state"] == "stopping"
    late = c.post("/api/requests", json={"item": 3})
    assert late.status_code == 409 and "stopping" in late.json()["error"]
    assert c.post("/api/pause").status_code == 409
    svc.thread.join(60)
    assert svc.code == 0
    assert c.get("/api/status").json()["state"] == "stopped"
    assert svc.service.get(first).state == "cancelled"
    ends = svc.records("request_end")
    assert [(e["id"], e["outcome"], e["reason"]) for e in ends] == [(first, "cancelled", "the service was stopped")]
    assert [(d["id"], d["reason"]) for d in svc.records("request_dropped")] == [(queued, "the service stopped")]
    run_end = svc.records("run_end")[0]
    assert run_end["outcome"] == "stopped" and run_end["exit_code"] == 0 and run_end["served"] == 1


def test_queue_full_is_429(live: Any, serve_config: Any) -> None:
    svc = live(config=serve_config("serve:\n  max_queue: 2\n"))
    c = svc.client
    c.post("/api/pause")
    for i in range(2):
        assert c.post("/api/requests", json={"item": i}).status_code == 202
    r = c.post("/api/requests", json={"item": 9})
    assert r.status_code == 429 and r.json()["error"] == "POST /api/requests: the queue is full (2 requests waiting)"


def test_token_is_required_when_given(live: Any) -> None:
    token = "t" * 32
    svc = live(token=token)
    c = svc.client
    for headers in ({}, {"Authorization": "Bearer wrong"}, {"Authorization": f"Basic {token}"}):
        r = c.get("/api/status", headers=headers)
        assert r.status_code == 401
        assert r.json()["error"] == "GET /api/status: a valid token is required (Authorization: Bearer TOKEN)"
    assert c.get("/openapi.json").status_code == 401
    assert c.post("/api/requests", json={"item": 1}).status_code == 401
    ok = {"Authorization": f"Bearer {token}"}
    assert c.get("/api/status", headers=ok).status_code == 200
    assert c.post("/api/requests", json={"item": 1}, headers=ok).status_code == 202
    with pytest.raises(WebSocketDisconnect) as e, c.websocket_connect("/api/stream"):
        pass
    assert e.value.code == 4401
    with c.websocket_connect(f"/api/stream?token={token}") as ws:
        assert ws.receive_json()["type"] == "hello"


def test_body_cap(live: Any, serve_config: Any) -> None:
    svc = live(config=serve_config("serve:\n  max_body: 2048\n"))
    c = svc.client
    big = json.dumps({"item": 1, "pad": "x" * 4096})
    r = c.post("/api/requests", content=big, headers={"content-type": "application/json"})
    assert r.status_code == 413 and r.json()["error"] == "POST /api/requests: body over 2048 bytes"

    def chunks() -> Any:  # no Content-Length: the cap counts what arrives
        for _ in range(5):
            yield b" " * 1000
    r = c.post("/api/requests", content=chunks(), headers={"content-type": "application/json"})
    assert r.status_code == 413
    assert c.post("/api/requests", json={"item": 1}).status_code == 202


def test_cors_closed_by_default_and_opened_by_config(missions: Path) -> None:
    from fastapi.testclient import TestClient

    mission = load_mission(missions / "quick.yaml")
    preflight = {"Origin": "http://evil.example", "Access-Control-Request-Method": "POST"}
    closed = TestClient(create_app(Service(mission, ServeSettings())))
    r = closed.options("/api/requests", headers=preflight)
    assert "access-control-allow-origin" not in r.headers
    r = closed.get("/api/status", headers={"Origin": "http://evil.example"})
    assert "access-control-allow-origin" not in r.headers
    settings = ServeSettings(cors_origins=["http://console.lab:8080"])
    opened = TestClient(create_app(Service(mission, settings)))
    r = opened.options("/api/requests", headers={**preflight, "Origin": "http://console.lab:8080"})
    assert r.headers["access-control-allow-origin"] == "http://console.lab:8080"
    r = opened.options("/api/requests", headers=preflight)
    assert r.headers.get("access-control-allow-origin") != "http://evil.example"
    # with a token, a preflight (which never carries one) is answered by the CORS layer alone
    guarded = TestClient(create_app(Service(mission, settings), token="s" * 32))
    r = guarded.options("/api/requests", headers={**preflight, "Origin": "http://console.lab:8080"})
    assert r.status_code == 200 and r.headers["access-control-allow-origin"] == "http://console.lab:8080"
    assert guarded.post("/api/requests", json={"item": 1}, headers={"Origin": "http://console.lab:8080"}
                        ).status_code == 401
    closed_guarded = TestClient(create_app(Service(mission, ServeSettings()), token="s" * 32))
    r = closed_guarded.options("/api/requests", headers=preflight)
    assert r.status_code == 405 and "access-control-allow-origin" not in r.headers


def test_no_files_are_served(live: Any) -> None:
    c = live().client
    for path in ("/static/../../etc/passwd", "/..%2f..%2fetc/passwd", "/config/mock.yaml", "/README.md"):
        r = c.get(path)
        assert r.status_code == 404, path
        assert "root:" not in r.text and "backend" not in r.text


def test_settings_are_checked_at_load(missions: Path, serve_config: Any) -> None:
    from mmexec.config.yamlload import InputError
    from mmexec.executive.runner import RunOptions
    from mmexec.executive.serve.service import ServeRunner

    config = serve_config("serve:\n  max_body: 10\n  cors_origins: ['*']\n  colour: red\n")
    runner = ServeRunner(RunOptions(mission=missions / "quick.yaml", config=config), Service())
    with pytest.raises(InputError) as e:
        runner.prepare()
    text = "\n".join(str(p) for p in e.value.problems)
    assert "serve.colour" in text or "colour" in text
    assert str(config) in text


def test_stream_events_tree_status_pose_and_scan(live: Any, stream_until: Any) -> None:
    svc = live()
    c = svc.client
    with c.websocket_connect("/api/stream") as ws:
        hello = ws.receive_json()
        assert hello["type"] == "hello" and hello["data"]["topics"] == list(TOPICS)
        rid = c.post("/api/requests", json={"item": 5}).json()["id"]
        msgs = stream_until(ws, lambda m: m["type"] == "event" and m["data"]["event"] == "request_end")
    kinds = {m["type"] for m in msgs}
    assert {"event", "tree", "status"} <= kinds
    events = [m["data"] for m in msgs if m["type"] == "event"]
    assert [e["event"] for e in events if e["event"].startswith("request_")] == [
        "request_queued", "request_start", "request_end"]
    assert [e["seq"] for e in events] == sorted(e["seq"] for e in events)
    logged = {r["seq"]: r for r in svc.records()}
    assert all(logged[e["seq"]] == e for e in events)  # exactly what the log holds
    trees = [m["data"] for m in msgs if m["type"] == "tree"]
    first = trees[0]
    assert first["request"] == rid
    assert [n["path"] for n in first["nodes"]] == svc.records("request_start")[0]["nodes"]
    assert first["nodes"][1]["parent"] == first["nodes"][0]["path"]
    final = {n["path"]: n["status"] for n in trees[-1]["nodes"]}
    assert set(final.values()) == {"SUCCESS"}
    with c.websocket_connect("/api/stream?topics=pose,scan") as ws:
        ws.receive_json()
        svc.runner.add_tick_hook(lambda robot, period: robot.lidar.scan())  # as a skill reading the lidar
        c.post("/api/requests", json={"item": 6})
        got = stream_until(ws, lambda m: m["type"] == "scan")
    pose = next(m for m in got if m["type"] == "pose")["data"]
    assert {"x", "y", "theta", "v", "w", "t"} <= set(pose)
    scan = next(m for m in got if m["type"] == "scan")["data"]
    assert len(scan["ranges"]) > 0 and scan["angle_increment"] > 0
    assert {m["type"] for m in got} <= {"pose", "scan"}


def test_camera_stream_shows_what_the_skills_read(live: Any, serve_config: Any, stream_until: Any) -> None:
    """On a stepped clock the stream never reads a sensor itself: the mock camera's 2nd
    read drops out whether or not a client watches, so request 2's prompt fails."""
    config = serve_config("")
    config.write_text(config.read_text().replace("  capabilities: [base, arm, gripper, camera, lidar]\n",
                                                 "  capabilities: [base, arm, gripper, camera, lidar]\n"
                                                 "  camera: {dropouts: [2]}\n"))
    svc = live("ask_point", config=config)
    c = svc.client
    with c.websocket_connect("/api/stream?topics=camera,prompt") as ws:
        ws.receive_json()
        first = c.post("/api/requests", json={"item": 1}).json()["id"]
        got = stream_until(ws, lambda m: m["type"] == "camera")
        prompt = next(m for m in got if m["type"] == "prompt")["data"]
        cam = next(m for m in got if m["type"] == "camera")["data"]
        assert base64.b64decode(cam["jpeg"])[:2] == b"\xff\xd8" and (cam["width"], cam["height"]) == (64, 48)
        t0 = c.get("/api/status").json()["t"]  # ticks pass while the prompt waits: the stream reads nothing
        svc.wait(lambda: c.get("/api/status").json()["t"] > t0 + 0.3, "ticks while the prompt waits")
        c.post(f"/api/prompts/{prompt['id']}/answer", json={"answer": [1, 1]})
        assert svc.finished(first)["state"] == "success"
        second = c.post("/api/requests", json={"item": 2}).json()["id"]
        end = svc.finished(second)
    assert end["state"] == "failure" and end["reason"] == "ask_operator: the camera has no frame to show"


def test_stream_unknown_topic(live: Any) -> None:
    c = live().client
    with c.websocket_connect("/api/stream?topics=event,bogus") as ws:
        msg = ws.receive_json()
        assert msg["type"] == "error"
        assert msg["data"]["error"].startswith("/api/stream: unknown topic 'bogus'")
        with pytest.raises(WebSocketDisconnect):
            ws.receive_json()


def test_a_client_joining_mid_request_gets_the_tree(live: Any, stream_until: Any) -> None:
    svc = live("ask_confirm")
    c = svc.client
    rid = c.post("/api/requests", json={"item": 1}).json()["id"]
    svc.prompt()
    with c.websocket_connect("/api/stream?topics=tree,status") as ws:
        assert ws.receive_json()["type"] == "hello"
        tree = stream_until(ws, lambda m: m["type"] == "tree")[-1]["data"]
    assert tree["request"] == rid
    status = {n["path"]: n["status"] for n in tree["nodes"]}
    assert status["ask_confirm/confirm"] == "RUNNING" and status["ask_confirm/report"] == "INVALID"
    assert c.get("/api/status").json()["tip"] == "ask_confirm/confirm"
