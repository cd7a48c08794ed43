"""End-to-end fruit picking on the UR5e sim (config/ur5e_sim.yaml, the lab's plant):
trees/pick_fruit.yaml with no request picks every fruit into the basket on the robot
(ground truth: each fruit's last state); with the plant moved out of the arm's reach the
mission fails naming why, with nothing held and the arm stowed; trees/fruit/click_pick.yaml
picks the fruit an operator clicks."""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from simkit import REPO

from mmexec.executive.config import LoadedConfig, build_robot
from mmexec.executive.eventlog import read_log
from mmexec.executive.runner import ArgMark, Progress, Request, Runner, RunOptions

pytestmark = pytest.mark.slow

UR5E_SIM = REPO / "config" / "ur5e_sim.yaml"
MISSION = REPO / "trees" / "pick_fruit.yaml"
LAB = REPO / "sim" / "worlds" / "lab.yaml"


def run_pick(tmp_path: Path, *, world: str | None = None, params: dict[str, Any] | None = None,
             seed: int = 0, mission: Path = MISSION,
             operator: Any = None) -> tuple[Any, list[dict[str, Any]], dict[str, Any], str]:
    """Run the mission once (one empty request); returns (the request's result, the event
    log, the robot's final truth: fruit states, held item, arm joints), the output."""
    text = UR5E_SIM.read_text()
    if world is not None:
        text = text.replace("\n  world: lab\n", f"\n  world: {world}\n", 1)
    cfg = tmp_path / "ur5e_sim.yaml"
    cfg.write_text(text)
    log = tmp_path / "events.jsonl"
    out = io.StringIO()
    holder: dict[str, Any] = {}

    def factory(loaded: LoadedConfig) -> Any:
        holder["robot"] = build_robot(loaded, seed=seed)
        return holder["robot"]

    opts = RunOptions(mission=mission, config=cfg, requests=[Request({}, ArgMark("test", 0, 0))],
                      params=dict(params or {}), seed=seed, log_path=log)
    runner = Runner(opts, out=out, err=out, progress=Progress(io.StringIO(), enabled=False), robot_factory=factory)
    truth: dict[str, Any] = {}

    def on_record(record: dict[str, Any]) -> None:
        if record.get("event") == "request_end":
            r = holder["robot"]
            truth["fruit"] = dict(r.scene_handles.plants.states)
            truth["held"] = r.truth.held_item()
            truth["arm"] = list(r.arm.state().positions)

    runner.add_log_listener(on_record)
    if operator is not None:
        from mmexec.skills.operator import OPERATOR_KEY

        operator.robot = lambda: holder["robot"]
        runner.world[OPERATOR_KEY] = operator
    runner.prepare()
    runner.run()
    return runner.results[0], read_log(log), truth, out.getvalue()


def test_every_fruit_ends_in_the_basket_on_the_robot(tmp_path: Path) -> None:
    result, log, truth, out = run_pick(tmp_path)
    assert result.outcome == "success", out
    assert truth["fruit"] and set(truth["fruit"].values()) == {"robot_basket"}, truth
    assert truth["held"] is None
    looks = [r for r in log if r.get("event") == "fruit_detections" and r["chosen"] is not None]
    assert len(looks) == len(truth["fruit"])  # one look and one choice per fruit: no retries
    for r in looks:  # the chosen detection is the highest-priority one of its look
        scores = [d["score"] for d in r["detections"]]
        assert scores[r["chosen"]] == max(scores)
    assert [r["picked"] for r in log if r.get("event") == "fruit_summary"] == [len(truth["fruit"])]


def test_a_plant_out_of_reach_fails_naming_why_with_the_robot_safe(tmp_path: Path) -> None:
    # the plant 0.35 m further west than the station expects: most fruit beyond the arm's reach
    world = tmp_path / "far_plant.yaml"
    world.write_text(LAB.read_text().replace("pose: [0.7, 0.75, 0.0]", "pose: [0.35, 0.75, 0.0]", 1))
    result, log, truth, out = run_pick(tmp_path, world=str(world))
    assert result.outcome == "failure", out
    assert "not picked after 2 attempts" in result.reason and "grasp candidates" in result.reason, result.reason
    # those within reach are in the basket, the others still hang: nothing knocked off or dropped
    assert "plant" in truth["fruit"].values() and set(truth["fruit"].values()) <= {"plant", "robot_basket"}
    assert truth["held"] is None
    tuck = [0.0, -1.9, 2.3, -1.97, -1.5708, 0.0]
    assert truth["arm"] == pytest.approx(tuck, abs=0.02)  # stowed before the verdict
    skipped = [r for r in log if r.get("event") == "fruit_skipped"]
    assert len(skipped) == list(truth["fruit"].values()).count("plant")


class TruthClicker:
    """An operator who clicks, on the current camera frame, the pixel where the true
    centre of fruit ``name`` appears (sim truth stands in for the person)."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.robot: Any = None
        self.pixel: list[float] | None = None

    def ask(self, prompt: Any) -> None:
        r = self.robot()
        f = r.camera.frame()
        T = np.linalg.inv(f.T_map_base @ f.T_base_camera)
        c = T @ np.append(r.scene_handles.plants.position(self.name), 1.0)
        uv = (f.intrinsics.matrix() @ c[:3])[:2] / c[2]
        self.pixel = [float(uv[0]), float(uv[1])]

    def poll(self, prompt_id: str, now: float) -> Any:
        from mmexec.skills.operator import Answer

        return Answer(self.pixel, "script")

    def close(self, prompt_id: str, reason: str) -> None:
        pass


def test_the_fruit_the_operator_clicks_is_picked(tmp_path: Path) -> None:
    clicker = TruthClicker("plant_fruit_5")  # the lab's upper green ball, in view from look_high
    result, log, truth, out = run_pick(tmp_path, mission=REPO / "trees" / "fruit" / "click_pick.yaml",
                                       operator=clicker)
    assert result.outcome == "success", out
    assert truth["fruit"]["plant_fruit_5"] == "robot_basket"
    assert list(truth["fruit"].values()).count("plant") == len(truth["fruit"]) - 1  # only that one
    click = [r for r in log if r.get("event") == "fruit_clicked"]
    assert len(click) == 1 and click[0]["method"] == "fit"
