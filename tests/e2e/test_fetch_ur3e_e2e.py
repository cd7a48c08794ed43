"""End-to-end fetch on the UR3e + Robotiq 2F-85 sim config (config/ur3e_sim.yaml): the
UR5e's platform and mission with the shorter arm (reach ~0.5 m, the UR5e 0.85 m), set up
by its profile alone. Item 1 stands on the far shelf's lower board, the hardest reach for
the UR3e: its wrist has to stay ahead of the base's front while the horizontal grasp
comes down to 0.30 m, so the base stops at the profile's first stand-off (0.74 m)."""

from __future__ import annotations

from pathlib import Path

from simkit import REPO, run_fetch

from mmexec.drivers.interfaces import Pose2D

UR3E_SIM = REPO / "config" / "ur3e_sim.yaml"


def test_ur3e_fetches_item_1_from_the_lower_board(tmp_path: Path) -> None:
    models: list[str] = []
    run = run_fetch(tmp_path, [1], config=UR3E_SIM, start=Pose2D(3.0, 2.0, 0.0),
                    setup=lambda robot, _runner: models.append(robot.description.name))
    assert models == ["ur3e_robotiq"]
    assert [r.outcome for r in run.results] == ["success"], run.out
    truth = run.truth[0]
    assert truth.in_depot.get("box_1") == "depot", (run.out, truth)
    assert truth.held is None
    assert [s["distance"] for s in run.events("standoff")] == [0.74], run.out
    assert not run.events("recovery_attempt"), run.out
