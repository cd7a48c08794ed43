"""What the browser console needs from the service, without a browser: its static files
(types, headers, nothing else reachable, no token needed for them alone), the mission's
request fields and node descriptions, the event-log tail, and the console's own streams
(blackboard, markers, people, marker detections on the camera frames, the scan's pose and
mount, the robot's facts in the status)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from fastapi.testclient import TestClient
from starlette.websockets import WebSocketDisconnect

from mmexec.executive.compiler import load_mission
from mmexec.executive.config import load_skill_modules
from mmexec.executive.serve.app import create_app
from mmexec.executive.serve.console import (
    BLACKBOARD_VALUE_CHARS,
    STATIC_DIR,
    WORLD_PEOPLE,
    StreamDetector,
    blackboard_json,
    mission_json,
    people_json,
    static_assets,
)
from mmexec.executive.serve.service import RECENT_EVENTS, Service
from mmexec.executive.serve.settings import ServeSettings
from mmexec.skills.perception.detect import WORLD_DETECTOR, WORLD_MARKERS, MarkerEstimate
from mmexec.skills.perception.markers import DetectorConfig, MarkerDetector

# --------------------------------------------------------------------------- static files


def test_console_files_with_their_types_and_headers(live: Any) -> None:
    c = live().client
    assert c.get("/").json()["console"] == "/console/"
    r = c.get("/console", follow_redirects=False)
    assert r.status_code == 307 and r.headers["location"] == "/console/"
    page = c.get("/console/")
    assert page.status_code == 200 and page.headers["content-type"] == "text/html; charset=utf-8"
    assert "default-src 'self'" in page.headers["content-security-policy"]
    assert page.headers["cache-control"] == "no-cache" and page.headers["x-content-type-options"] == "nosniff"
    assert page.text == (STATIC_DIR / "index.html").read_text()
    for name, kind in (("app.js", "text/javascript; charset=utf-8"), ("style.css", "text/css; charset=utf-8")):
        r = c.get(f"/console/{name}")
        assert (r.status_code, r.headers["content-type"]) == (200, kind)
        assert "content-security-policy" not in r.headers
    assert c.head("/console/app.js").status_code == 200
    assert "/console/" not in c.get("/openapi.json").json()["paths"]


def test_every_console_file_is_a_known_type_and_loads_only_its_own() -> None:
    assets = static_assets()
    assert {"index.html", "app.js", "style.css"} <= set(assets)
    on_disk = sorted(p.relative_to(STATIC_DIR).as_posix() for p in STATIC_DIR.rglob("*") if p.is_file())
    assert sorted(assets) == on_disk  # nothing in the folder is left unserved (or unknown)
    for name, asset in assets.items():
        text = asset.path.read_text()
        assert "http://" not in text and "https://" not in text, f"{name}: no CDN, no internet at run time"


@pytest.mark.parametrize("path", [
    "/console/../executive/serve/app.py", "/console/%2e%2e/console.py", "/console/..%2fconsole.py",
    "/console/%2fetc%2fpasswd", "/console/console.py", "/console/static/app.js", "/console/.%2fapp.js",
])
def test_nothing_but_the_console_files(live: Any, path: str) -> None:
    r = live().client.get(path)
    assert r.status_code in (401, 404), path  # 401: the client normalised it to an API path
    assert "error" in r.json()


def test_links_and_files_outside_are_not_listed(tmp_path: Path) -> None:
    static = tmp_path / "static"
    (static / "sub").mkdir(parents=True)
    (static / "index.html").write_text("<p>ok</p>")
    (static / "sub" / "x.js").write_text("export {};")
    (static / "notes.py").write_text("secret = 1")
    (tmp_path / "outside.js").write_text("outside")
    (static / "link.js").symlink_to(tmp_path / "outside.js")
    (static / "dir").symlink_to(tmp_path)
    assert sorted(static_assets(static)) == ["index.html", "sub/x.js"]


def test_the_console_needs_no_token_the_api_does(missions: Path) -> None:
    load_skill_modules(None)
    mission = load_mission(missions / "quick.yaml")
    c = TestClient(create_app(Service(mission, ServeSettings()), token="s" * 32))
    assert c.get("/console/").status_code == 200
    assert c.get("/console/app.js").status_code == 200
    assert c.get("/api/mission").status_code == 401
    assert c.get("/api/mission", headers={"Authorization": "Bearer " + "s" * 32}).json()["name"] == "quick"
    assert c.post("/console/app.js").status_code == 401  # only reading the files is open


# --------------------------------------------------------------------------- mission, events


MISSION = """\
mission: shapes
description: One of each node the console labels.
params:
  places: {type: list, default: [a, b], doc: "where"}
requests:
  item: {type: int, doc: "the item"}
  note: {type: str, doc: "a note"}
tree:
  sequence:
    - condition: request.item
      op: ">="
      value: 0
    - recovery:
        action: {skill: close_gripper, outputs: {holding: held}}
        recovery: {skill: open_gripper}
        max_recoveries: 1
        give_up: {skill: report, params: {message: "gave up: {grip.last_failure}"}}
      name: grip
    - if: {condition: held, op: "==", value: true}
      then: {skill: report, params: {message: "holding {request.item}"}}
      else: {skill: report, params: {message: "empty"}}
    - foreach: "{places}"
      as: place
      do: {skill: report, params: {message: "at {place}"}}
"""


def test_mission_json_fields_kinds_branches_and_keys(tmp_path: Path) -> None:
    load_skill_modules(None)
    path = tmp_path / "shapes.yaml"
    path.write_text(MISSION)
    info = mission_json(load_mission(path))
    assert info["name"] == "shapes" and info["description"] == "One of each node the console labels."
    assert info["requests"] == [{"name": "item", "type": "int", "doc": "the item"},
                                {"name": "note", "type": "str", "doc": "a note"}]
    assert info["params"] == [{"name": "places", "type": "list", "doc": "where", "default": ["a", "b"]}]
    nodes = {n["path"]: n for n in info["nodes"]}
    assert info["nodes"][0]["path"] == "shapes"
    grip = nodes["shapes/grip"]
    assert grip["kind"] == "recovery" and grip["detail"] == "recovery, at most 1 recoveries"
    assert grip["writes"] == ["grip.attempts", "grip.last_failure", "grip.outcome", "grip.recoveries"]
    branches = {n["branch"]: n for n in info["nodes"] if n["path"].startswith("shapes/grip/")}
    assert set(branches) == {"action", "recovery", "give_up"}
    assert branches["action"]["writes"] == ["held"] and branches["give_up"]["reads"] == ["grip.last_failure"]
    cond = nodes["shapes/condition"]
    assert (cond["kind"], cond["reads"], cond["detail"]) == ("leaf", ["request.item"], "request.item >= 0")
    labels = [n["branch"] for n in info["nodes"] if n["path"].startswith("shapes/if/")]
    assert labels == ["if", "then", "else"]
    loop = next(n for n in info["nodes"] if n["detail"].startswith("foreach"))
    assert loop["writes"] == ["place"]


def test_mission_and_events_endpoints(live: Any) -> None:
    svc = live()
    c = svc.client
    info = c.get("/api/mission").json()
    assert info["name"] == "quick" and info["requests"] == [{"name": "item", "type": "int", "doc": "any number"}]
    assert [n["path"] for n in info["nodes"]] == ["quick", "quick/report", "quick/wait"]
    rid = c.post("/api/requests", json={"item": 4}).json()["id"]
    svc.finished(rid)
    logged = svc.records()
    tail = svc.wait(lambda: (got := c.get("/api/events?limit=5").json())[-1]["event"] == "request_end" and got)
    assert tail == logged[-5:] and len(tail) == 5
    assert c.get("/api/events?limit=0").json() == []
    assert c.get("/api/events").json() == logged[-200:]
    r = c.get(f"/api/events?limit={RECENT_EVENTS + 1}")
    assert r.status_code == 422 and r.json()["error"].startswith("GET /api/events: query.limit:")


def test_mission_before_one_is_loaded_is_409() -> None:
    c = TestClient(create_app(Service()))
    r = c.get("/api/mission")
    assert r.status_code == 409 and r.json() == {"error": "GET /api/mission: no mission is loaded yet"}


# --------------------------------------------------------------------------- streams


def test_blackboard_markers_people_and_robot_facts(live: Any, stream_until: Any) -> None:
    svc = live("ask_confirm")
    c = svc.client
    world = svc.runner.world
    T = np.eye(4)
    T[:3, :3] = [[0, 0, -1], [0, 1, 0], [1, 0, 0]]  # face normal (z) along -x of map: yaw pi
    T[:3, 3] = [2.0, 1.0, 0.5]

    def hook(robot: Any, period: float) -> None:  # as a detection skill and the navigation stack would
        robot.lidar.scan()
        if WORLD_MARKERS not in world:
            world[WORLD_MARKERS] = {7: MarkerEstimate(7, T, 3, robot.clock.now(), 1.2)}
            world[WORLD_PEOPLE] = [[1.0, 2.0, 0.5, -0.25], {"id": "p9", "x": 3, "y": 4}]

    svc.runner.add_tick_hook(hook)
    with c.websocket_connect("/api/stream?topics=blackboard,markers,people") as ws:
        assert ws.receive_json()["type"] == "hello"
        rid = c.post("/api/requests", json={"item": 5}).json()["id"]
        prompt = svc.prompt()
        wanted = {"markers", "people", "blackboard"}

        def seen_all(m: dict[str, Any]) -> bool:
            if m["type"] != "blackboard" or m["data"]["values"].get("request.item") == 5:
                wanted.discard(m["type"])
            return not wanted

        got = stream_until(ws, seen_all)
        c.post(f"/api/prompts/{prompt['id']}/answer", json={"answer": True})
        final = stream_until(ws, lambda m: m["type"] == "blackboard" and "confirmed" in m["data"]["values"])[-1]
    assert svc.finished(rid)["state"] == "success"
    assert final["data"]["values"]["confirmed"] is True and final["data"]["values"]["who"] == "api"
    markers = next(m for m in got if m["type"] == "markers")["data"]["markers"]
    assert len(markers) == 1 and markers[0]["id"] == 7 and markers[0]["samples"] == 3
    assert [markers[0][k] for k in ("x", "y", "z")] == [2.0, 1.0, 0.5]
    assert markers[0]["yaw"] == pytest.approx(math.pi)
    people = next(m for m in got if m["type"] == "people")["data"]["people"]
    assert people == [{"id": 0, "x": 1.0, "y": 2.0, "vx": 0.5, "vy": -0.25},
                      {"id": "p9", "x": 3.0, "y": 4.0, "vx": 0.0, "vy": 0.0}]
    robot = c.get("/api/status").json()["robot"]
    assert robot["name"] == "mock" and robot["footprint_radius"] > 0
    with c.websocket_connect("/api/stream?topics=blackboard,markers") as ws:  # sticky: a new client gets them
        assert ws.receive_json()["type"] == "hello"
        kinds = {ws.receive_json()["type"], ws.receive_json()["type"]}
    assert kinds == {"blackboard", "markers"}


def test_a_scan_comes_with_the_base_pose_and_the_lidar_mount(live: Any, stream_until: Any) -> None:
    svc = live()
    c = svc.client
    svc.runner.add_tick_hook(lambda robot, period: robot.lidar.scan())  # as a skill reading the lidar
    with c.websocket_connect("/api/stream?topics=scan") as ws:  # no pose subscriber: the scan still has it
        assert ws.receive_json()["type"] == "hello"
        c.post("/api/requests", json={"item": 1})
        scan = stream_until(ws, lambda m: m["type"] == "scan")[-1]["data"]
    mount = svc.runner.robot.lidar.scan().T_base_lidar
    assert scan["lidar"] == pytest.approx([mount[0, 3], mount[1, 3], math.atan2(mount[1, 0], mount[0, 0])])
    assert len(scan["pose"]) == 3 and all(math.isfinite(v) for v in scan["pose"])


def test_a_camera_frame_comes_with_its_detections(live: Any, stream_until: Any) -> None:
    svc = live("ask_point")
    c = svc.client
    world = svc.runner.world
    svc.runner.add_tick_hook(lambda robot, period: world.setdefault(  # as a detection skill would
        WORLD_DETECTOR, MarkerDetector(DetectorConfig(downscale=1))))
    with c.websocket_connect("/api/stream?topics=camera,prompt") as ws:
        assert ws.receive_json()["type"] == "hello"
        c.post("/api/requests", json={"item": 1})
        cam = stream_until(ws, lambda m: m["type"] == "camera")[-1]["data"]
        prompt = svc.prompt()
        c.post(f"/api/prompts/{prompt['id']}/answer", json={"answer": [1, 1]})
    assert cam["detections"] == []  # the mock's image shows no marker
    found = svc.runner.console.detections(_tag_image(4))  # the same detector on one that does
    assert [d["id"] for d in found] == [4]


def _tag_image(marker: int) -> np.ndarray:
    """A 320x240 RGB image with ``marker`` (DICT_4X4_50, 80 px) at x 100..180, y 60..140."""
    img = np.full((240, 320), 255, np.uint8)
    img[60:140, 100:180] = cv2.aruco.generateImageMarker(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50),
                                                         marker, 80)
    return np.dstack([img] * 3)


def test_stream_detector_finds_a_marker_with_its_corners() -> None:
    cfg = DetectorConfig()
    rgb = _tag_image(4)
    assert StreamDetector().detect({}, rgb) == []  # no skill made a detector yet: nothing to match
    found = StreamDetector().detect({WORLD_DETECTOR: MarkerDetector(cfg)}, rgb)
    assert [d["id"] for d in found] == [4] and found[0]["label"] == "marker 4"
    xs, ys = zip(*found[0]["points"])
    assert min(xs) == pytest.approx(100, abs=1.5) and max(xs) == pytest.approx(180, abs=1.5)
    assert min(ys) == pytest.approx(60, abs=1.5) and max(ys) == pytest.approx(140, abs=1.5)


def test_people_and_blackboard_payloads() -> None:
    assert people_json(None) == []
    assert people_json([[1, 2], [float("nan"), 0], ["a", 1], {"x": 1}, (0.5, 0.5, 1, 1)]) == [
        {"id": 0, "x": 1.0, "y": 2.0, "vx": 0.0, "vy": 0.0}, {"id": 4, "x": 0.5, "y": 0.5, "vx": 1.0, "vy": 1.0}]
    values = blackboard_json({"b": np.arange(3), "a": float("inf"), "long": "x" * 3000})
    assert list(values) == ["a", "b", "long"] and values["b"] == [0, 1, 2] and values["a"] == "inf"
    assert len(values["long"]) == BLACKBOARD_VALUE_CHARS + 3 and values["long"].endswith("...")


def test_unknown_topic_names_the_console_topics(live: Any) -> None:
    with live().client.websocket_connect("/api/stream?topics=blackbored") as ws:
        msg = ws.receive_json()
        assert "prompt, blackboard, markers, people)" in msg["data"]["error"]
        with pytest.raises(WebSocketDisconnect):
            ws.receive_json()
