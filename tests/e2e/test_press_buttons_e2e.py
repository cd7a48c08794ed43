"""End-to-end button presser on the UR5e + 2F-85 sim config (config/ur5e_sim.yaml):
trees/press_buttons.yaml with no request presses every button of the lab's panel, checked
against the sim's ground truth (every light on, each press within 5 mm of its button's
centre); a request ``buttons=[b3,b1]`` presses those two in that order and no other; with
the panel's markers hidden it gives up with the reason, at home, the base stopped and the
arm held."""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from mmexec.executive.config import LoadedConfig, build_robot
from mmexec.executive.eventlog import read_log
from mmexec.executive.runner import ArgMark, Progress, Request, Runner, RunOptions

REPO = Path(__file__).resolve().parents[2]
MISSION = REPO / "trees" / "press_buttons.yaml"
UR5E_SIM = REPO / "config" / "ur5e_sim.yaml"

pytestmark = pytest.mark.slow


def _run(tmp_path: Path, setup: Any = None, seed: int = 0,
         requests: list[Request] | None = None) -> tuple[int, Runner, Any, list[dict[str, Any]]]:
    holder: dict[str, Any] = {}

    def factory(loaded: LoadedConfig) -> Any:
        robot = build_robot(loaded, seed=seed)
        holder["robot"] = robot
        if setup is not None:
            setup(robot)
        return robot

    log = tmp_path / "events.jsonl"
    out = io.StringIO()
    runner = Runner(RunOptions(mission=MISSION, config=UR5E_SIM, requests=requests or [], seed=seed, log_path=log), out=out,
                    err=out, progress=Progress(io.StringIO(), enabled=False), robot_factory=factory)
    at_end: dict[str, Any] = {}

    def on_record(record: dict[str, Any]) -> None:
        if record.get("event") == "request_end":
            r = holder["robot"]
            at_end.update(lights=r.scene_handles.panels.lights(), presses=list(r.scene_handles.panels.presses),
                          base=r.truth.base_pose(), v=r.base.state(), arm=r.arm.state(), arm_rest=r.arm.at_rest())

    runner.add_log_listener(on_record)
    runner.prepare()
    code = runner.run()
    return code, runner, at_end, read_log(log)


def test_every_button_pressed_within_5_mm(tmp_path: Path) -> None:
    code, runner, truth, records = _run(tmp_path)
    assert code == 0 and [r.outcome for r in runner.results] == ["success"]
    assert truth["lights"] == {"panel/b1": True, "panel/b2": True, "panel/b3": True}
    switched = [p for p in truth["presses"] if p.switched]
    assert [p.button for p in switched] == ["b1", "b2", "b3"]  # left to right, once each
    assert all(p.offset is not None and p.offset <= 0.005 for p in switched), [p.record() for p in switched]
    result = next(r for r in records if r["event"] == "buttons_result")
    assert result["outcomes"] == {"b1": "pressed", "b2": "pressed", "b3": "pressed"} and result["trajectories"] == "6/6"
    fit = next(r for r in records if r["event"] == "panel_fit")
    assert len(fit["markers"]) >= 5 and fit["rms_mm"] < 3.0
    assert truth["base"].distance_to(type(truth["base"])(1.5, 2.0, 0.0)) < 0.15  # back home


def test_requested_buttons_in_the_requested_order(tmp_path: Path) -> None:
    code, runner, truth, records = _run(tmp_path, requests=[Request({"buttons": "[b3,b1]"}, ArgMark("--request", 1, 1))])
    assert code == 0 and [r.outcome for r in runner.results] == ["success"]
    assert truth["lights"] == {"panel/b1": True, "panel/b2": False, "panel/b3": True}
    assert [p.button for p in truth["presses"] if p.switched] == ["b3", "b1"]
    result = next(r for r in records if r["event"] == "buttons_result")
    assert result["outcomes"] == {"b3": "pressed", "b1": "pressed"} and result["trajectories"] == "4/4"


def test_hidden_panel_markers_give_up_at_home_safely(tmp_path: Path) -> None:
    code, runner, truth, records = _run(tmp_path, setup=lambda r: r.scene_handles.panels.hide_markers("panel"))
    assert code == 1 and [r.outcome for r in runner.results] == ["failure"]
    reason = runner.results[0].reason
    assert "of its markers seen" in reason, reason
    reports = [r["message"] for r in records if r["event"] == "report"]
    assert sum("repositioning" in m for m in reports) == 2 and any(m.startswith("buttons not pressed") for m in reports)
    assert truth["presses"] == [] and not any(truth["lights"].values())
    assert abs(truth["v"].v) < 1e-3 and abs(truth["v"].w) < 1e-3  # the base stopped
    assert truth["arm_rest"] or float(np.max(np.abs(truth["arm"].velocities))) < 1e-2  # the arm held
    assert truth["base"].distance_to(type(truth["base"])(1.5, 2.0, 0.0)) < 0.15  # gave up at home
