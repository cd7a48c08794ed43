"""End-to-end fetch on the UR5e + Robotiq 2F-85 sim config (config/ur5e_sim.yaml): the
same mission as the LoCoBot, one item from the far shelf's upper board into the depot.
Checks the 2F-85 grasp design (grasp_height: the body clears the board under a 6 cm box)
and the sim's Robotiq hold (a centred grasp is not a slipping one)."""

from __future__ import annotations

from pathlib import Path

from simkit import REPO, run_fetch

from mmexec.drivers.interfaces import Pose2D

UR5E_SIM = REPO / "config" / "ur5e_sim.yaml"


def test_ur5e_fetches_item_3_into_the_depot(tmp_path: Path) -> None:
    run = run_fetch(tmp_path, [3], config=UR5E_SIM, start=Pose2D(3.0, 2.0, 0.0))
    assert [r.outcome for r in run.results] == ["success"], run.out
    truth = run.truth[0]
    assert truth.in_depot.get("box_3") == "depot", (run.out, truth)
    assert truth.held is None
    plans = [r["what"] for r in run.events("arm_plan")]
    assert "grasp approach" in plans and "place retract" in plans
    assert not run.events("recovery_attempt"), run.out
