"""The service on the sim backend: a request through the API whose ask_operator shows the
simulated camera image, answered through the API, while the stream carries the map and
the pose; the stepped clock holds still between requests."""

from __future__ import annotations

from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]


def test_sim_request_with_a_point_prompt(live: Any) -> None:
    svc = live("ask_point", config=ROOT / "config" / "locobot_sim.yaml")
    c = svc.client
    t_idle = c.get("/api/status").json()["t"]
    with c.websocket_connect("/api/stream?topics=map,pose,prompt") as ws:
        first = ws.receive_json()
        assert first["type"] == "hello" and first["data"]["status"]["backend"] == "sim"
        grid = ws.receive_json()
        assert grid["type"] == "map" and grid["data"]["width"] > 0 and grid["data"]["resolution"] > 0
        rid = c.post("/api/requests", json={"item": 3}).json()["id"]
        prompt = None
        while prompt is None:
            msg = ws.receive_json()
            if msg["type"] == "prompt" and msg["data"]["action"] == "prompt":
                prompt = msg["data"]
    w, h = prompt["image_size"]
    img = c.get(prompt["image_url"])
    assert img.status_code == 200 and img.content[:2] == b"\xff\xd8" and w > 0 and h > 0
    r = c.post(f"/api/prompts/{prompt['id']}/answer", json={"answer": [w / 2, h / 2]})
    assert r.status_code == 200
    assert svc.finished(rid)["state"] == "success"
    assert svc.close() == 0
    answer = svc.records("operator_answer")[0]
    assert answer["answer"] == [w / 2, h / 2] and answer["source"] == "api"
    assert svc.records("run_start")[0]["backend"] == "sim"
    assert svc.records("request_queued")[0]["t"] == t_idle  # idle: the sim clock did not move
