"""End-to-end fetch_object (issue 15): untagged objects requested by name in the
`lab_objects` world on the simulated LoCoBot (trees/fetch_object.yaml,
config/locobot_objects_sim.yaml), checked with the sim's ground truth: the object in the
depot basket, which parts of a dangerous object the pads held, the robot safe at home
after a prompt nobody answered."""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import pytest
from simkit import REPO

from mmexec.executive.config import LoadedConfig, build_robot
from mmexec.executive.eventlog import read_log
from mmexec.executive.runner import ArgMark, Progress, Request, Runner, RunOptions
from mmexec.executive.serve.prompts import ScriptedAnswers, load_answers
from mmexec.executive.sim_operator import sim_click_operator
from mmexec.sim.objects import parts_touched
from mmexec.skills.operator import OPERATOR_KEY

MISSION = REPO / "trees" / "fetch_object.yaml"
CONFIG = REPO / "config" / "locobot_objects_sim.yaml"
SIM_CLICK = REPO / "config" / "answers" / "sim_click.yaml"

pytestmark = pytest.mark.slow


def run_objects(tmp_path: Path, items: list[str], *, answers: Path | None = None, seed: int = 0,
                edit: tuple[str, str] | None = None, config: Path = CONFIG) -> dict[str, Any]:
    """Serve one ``item=NAME`` request per entry (in-process Runner, as ``mmexec run``),
    with ``answers`` as ``--answers`` and ``edit`` (old, new) applied to the config text;
    returns the results, the event log and the robot (for its ground truth)."""
    text = config.read_text()
    if edit is not None:
        assert edit[0] in text
        text = text.replace(edit[0], edit[1])
    cfg = tmp_path / config.name
    cfg.write_text(text)
    log_path = tmp_path / "events.jsonl"
    out = io.StringIO()
    reqs = [Request({"item": k}, ArgMark("--request", i, 1)) for i, k in enumerate(items, start=1)]
    opts = RunOptions(mission=MISSION, config=cfg, requests=reqs, seed=seed, log_path=log_path)
    holder: dict[str, Any] = {}

    def factory(loaded: LoadedConfig) -> Any:
        holder["robot"] = build_robot(loaded, seed=seed)
        return holder["robot"]

    runner = Runner(opts, out=out, err=out, progress=Progress(io.StringIO(), enabled=False), robot_factory=factory)
    truth: list[dict[str, Any]] = []

    def on_record(record: dict[str, Any]) -> None:
        if record.get("event") == "request_end":  # SIM-ONLY ground truth, before the robot closes
            robot = holder["robot"]
            t = robot.truth
            pose = t.base_pose()
            objects = {o.name: o for o in robot.world.spec.objects}
            truth.append({"in_depot": {n: t.in_depot(n) for n in robot.world.object_names()}, "held": t.held_item(),
                          "base": (pose.x, pose.y), "z": {n: float(t.item_pose(n)[2, 3]) for n in objects},
                          "grasps": [(g[1], parts_touched(objects, g[1], g[2])) for g in robot.core.grasps]})

    runner.add_log_listener(on_record)
    runner.prepare()
    if answers is not None:
        sim = sim_click_operator(answers, lambda: runner.robot, seed)
        runner.world[OPERATOR_KEY] = sim or ScriptedAnswers(load_answers(answers), answers)
    code = runner.run()
    return {"code": code, "results": list(runner.results), "records": read_log(log_path), "truth": truth,
            "out": out.getvalue(), "operator": runner.world.get(OPERATOR_KEY)}


def events(run: dict[str, Any], name: str) -> list[dict[str, Any]]:
    return [r for r in run["records"] if r.get("event") == name]


def at_home(truth: dict[str, Any], tol: float = 0.3) -> bool:
    x, y = truth["base"]
    return abs(x - 1.5) < tol and abs(y - 2.0) < tol


def test_fetches_an_untagged_pen_from_the_table(tmp_path: Path) -> None:
    run = run_objects(tmp_path, ["pen"])
    assert [r.outcome for r in run["results"]] == ["success"], run["out"]
    truth = run["truth"][0]
    assert truth["in_depot"]["pen"] == "depot"
    assert truth["held"] is None and at_home(truth)
    found = events(run, "object_found")
    assert found and found[0]["place"] == "table_front" and found[0]["likely"]
    grasp = events(run, "object_grasp")[-1]
    assert grasp["mode"] == "top"
    # the grasp point the pick used lies within 1.5 cm of the pen's true centre of mass
    # (it was true where the pen lay; the pen is in the basket now, so check it by the estimate's
    # support height and the world's nominal table position)
    assert abs(grasp["centre"][2] - 0.32) < 0.015
    assert not events(run, "operator_prompt")


def test_a_dangerous_screwdriver_is_held_by_its_blade_after_the_operators_click(tmp_path: Path) -> None:
    run = run_objects(tmp_path, ["screwdriver"], answers=SIM_CLICK)
    assert [r.outcome for r in run["results"]] == ["success"], run["out"]
    truth = run["truth"][0]
    assert truth["in_depot"]["screwdriver"] == "depot"
    fix = events(run, "grasp_corrected")
    assert len(fix) == 1
    pred, click, corr = fix[0]["predicted"], fix[0]["clicked"], fix[0]["corrected"]
    assert corr == pytest.approx([(pred[0] + click[0]) / 2, (pred[1] + click[1]) / 2])
    # the click was the operator's (the sim's truth of the blade's pixel, 3 px noise)
    op = run["operator"]
    assert len(op.clicks) == 1 and op.clicks[0][1] == "screwdriver"
    # truth: the pads closed on the blade (the dangerous part), not only on the handle
    grasps = [parts for item, parts in truth["grasps"] if item == "screwdriver"]
    assert grasps, "the screwdriver was never grasped"
    assert "blade" in grasps[-1], grasps


def test_no_answer_within_the_timeout_fails_the_request_cleanly_at_home(tmp_path: Path) -> None:
    answers = tmp_path / "late.yaml"
    answers.write_text("- {answer: [256, 200], kind: point, after: 1000}\n")
    run = run_objects(tmp_path, ["screwdriver"], answers=answers,
                      edit=("    operator_timeout: 60.0\n", "    operator_timeout: 5.0\n"))
    assert [r.outcome for r in run["results"]] == ["failure"], run["out"]
    truth = run["truth"][0]
    closed = events(run, "operator_prompt_closed")
    assert [c["reason"] for c in closed] == ["timeout"]  # asked once: a timeout is not retried
    assert len(events(run, "operator_prompt")) == 1
    # safe: nothing held, the screwdriver still on its table, the arm stowed, the base at home
    assert truth["held"] is None and not truth["grasps"]
    assert truth["z"]["screwdriver"] > 0.3
    assert at_home(truth)
    stow = [r for r in events(run, "arm_plan") if r["what"] == "arm to tuck"]
    assert stow, "the arm was not stowed on the way home"
    assert not events(run, "object_grasp")


def test_a_box_behind_a_crate_is_fetched_from_the_holistic_planners_base_pose(tmp_path: Path) -> None:
    # lab_objects_blocked: a low crate in front of the far shelf's red box leaves no free
    # stand-off facing it; the holistic planner (base x, y, yaw + arm) finds where to stand
    run = run_objects(tmp_path, ["box_red"], edit=("  world: lab_objects\n", "  world: lab_objects_blocked\n"))
    assert [r.outcome for r in run["results"]] == ["success"], run["out"]
    truth = run["truth"][0]
    assert truth["in_depot"]["box_red"] == "depot"
    failures = [r for r in events(run, "skill_failure") if r["skill"] == "approach_object"]
    assert failures and "no free stand-off" in failures[0]["reason"]
    plans = events(run, "holistic_plan")
    assert plans and plans[-1]["success"]
    assert [g for g in events(run, "object_grasp") if g["mode"] == "front"]


def test_the_ur5e_fetches_the_pliers_with_its_wrist_camera(tmp_path: Path) -> None:
    # the same mission on the UR5e platform: one wrist view per scan, look_near from the
    # stand-off, a top grasp corrected by the operator's click on the head
    run = run_objects(tmp_path, ["pliers"], answers=SIM_CLICK, config=REPO / "config" / "ur5e_objects_sim.yaml")
    assert [r.outcome for r in run["results"]] == ["success"], run["out"]
    truth = run["truth"][0]
    assert truth["in_depot"]["pliers"] == "depot"
    assert "head" in [parts for item, parts in truth["grasps"] if item == "pliers"][-1]
    assert events(run, "object_estimate")[-1]["where"] == "stand-off"  # seen again from the stand-off
