"""The fetch mission where the marker's front is blocked (sim world ``lab_blocked``: a low
crate on the floor against the far shelf, in front of box 1): no stand-off along the
marker's normal is free, so trees/fetch/approach.yaml falls back to the holistic planner
(base and arm planned together to the pick's pre-grasp from the marker's grasp frame),
the base stands beside the crate, looks at the marker again from there and the pick
reaches in over the crate. Without the holistic planner (``holistic: false``) the
approach gives up and the request fails at home. Asserted on the event log and on the
sim's ground truth (the box in the depot)."""

from __future__ import annotations

from pathlib import Path

import pytest
from simkit import LOCOBOT_SIM, run_fetch

from mmexec.drivers.interfaces import Pose2D

pytestmark = pytest.mark.slow

FACING_FAR_SHELF = Pose2D(3.0, 2.0, 0.0)  # marker 1 in view: no search
#: the crate in front of box 1 (sim/worlds/lab_blocked.yaml): centre y, half its width [m]
CRATE_Y, CRATE_HALF_WIDTH = 2.3, 0.15


def _blocked_config(tmp_path: Path) -> Path:
    text = LOCOBOT_SIM.read_text()
    assert "  world: lab\n" in text
    path = tmp_path / "locobot_blocked.yaml"
    path.write_text(text.replace("  world: lab\n", "  world: lab_blocked\n", 1))
    return path


def test_a_marker_whose_front_is_blocked_is_picked_from_a_holistic_stand_off(tmp_path: Path) -> None:
    run = run_fetch(tmp_path, [1], start=FACING_FAR_SHELF, config=_blocked_config(tmp_path))
    assert [r.outcome for r in run.results] == ["success"], run.out
    (blocked,) = [r for r in run.events("skill_failure") if r.get("skill") == "approach"]
    assert blocked["kind"] == "planning" and "no free stand-off" in blocked["reason"]
    plans = run.events("holistic_plan")
    assert plans and plans[-1]["success"]
    y = plans[-1]["pose"][1]
    assert abs(y - CRATE_Y) > CRATE_HALF_WIDTH  # beside the crate, not in front of the box
    # the marker looked at again from where the base stopped, close by
    (relocated,) = [r for r in run.events("marker_estimate") if r.get("node", "").endswith("relocate_marker")]
    assert relocated["distance"] < 0.8
    assert not run.events("recovery_attempt")  # neither the approach's nor the pick's recovery ran
    truth = run.truth[0]
    assert truth.in_depot.get("box_1") == "depot", (run.out, truth)
    assert truth.held is None
    assert run.exit_code == 0


def test_without_the_holistic_planner_the_blocked_marker_is_given_up_at_home(tmp_path: Path) -> None:
    run = run_fetch(tmp_path, [1], start=FACING_FAR_SHELF, config=_blocked_config(tmp_path),
                    params={"holistic": False})
    assert [r.outcome for r in run.results] == ["failure"], run.out
    assert not [r for r in run.events("holistic_plan")]
    failures = [r for r in run.events("skill_failure") if r.get("skill") == "holistic_standoff"]
    assert len(failures) == 3 and all("holistic planner off" in r["reason"] for r in failures)
    reports = [r["message"] for r in run.events("report")]
    assert "marker 1: no reachable stand-off pose; resetting" in reports
    assert run.truth[0].held is None and run.truth[0].in_depot.get("box_1") != "depot"
    assert run.truth[0].base.distance_to(Pose2D(1.5, 2.0, 0.0)) < 0.15  # reset: at home
