"""End-to-end fetch scenarios on the pybullet `lab` world (config/locobot_sim.yaml):
the mission trees/fetch_item.yaml served by the executive's Runner, asserted on the
event log (requests, searches, recoveries) and on sim ground truth (items in the depot).
Each test builds one simulated robot and serves its requests with it."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from simkit import SimRun, run_fetch

from mmexec.drivers.interfaces import Pose2D
from mmexec.executive.runner import Runner

HOME = Pose2D(1.5, 2.0, 0.0)           # profile home = the lab's start pose
FACING_FAR_SHELF = Pose2D(3.0, 2.0, 0.0)  # 1.7 m in front of the far shelf (boxes 1-3 in view)


def _outcomes(run: SimRun) -> list[str]:
    return [r.outcome for r in run.results]


def _skills_started(run: SimRun, skill: str, request: int | None = None) -> list[dict[str, Any]]:
    return [r for r in run.events("skill_start", request) if r.get("skill") == skill]


def _assert_delivered(run: SimRun, request: int, box: str) -> None:
    truth = run.truth[request - 1]
    assert truth.in_depot.get(box) == "depot", (run.out, truth)
    assert truth.held is None


def _at_home(run: SimRun, request: int) -> bool:
    return run.truth[request - 1].base.distance_to(HOME) < 0.15


def test_item_in_view_is_fetched_without_searching(tmp_path: Path) -> None:
    run = run_fetch(tmp_path, [3], start=FACING_FAR_SHELF)
    assert _outcomes(run) == ["success"], run.out
    assert _skills_started(run, "search") == []
    detect = [r for r in run.events("skill_success") if r.get("skill") == "detect_marker"]
    assert len(detect) == 1
    assert run.results[0].recoveries == 0 and not run.events("recovery_attempt")
    _assert_delivered(run, 1, "box_3")
    assert _at_home(run, 1)
    assert run.exit_code == 0


def test_item_behind_the_robot_is_found_by_turning(tmp_path: Path) -> None:
    # box 5 is on the near shelf, behind the robot: 0.6 m further north than the lab's start,
    # so the view that turns to it sees its marker nearly face-on (from the start itself
    # it is seen only obliquely, and whether a 30-degree view catches it depends on where
    # the localised turn stops to a degree)
    run = run_fetch(tmp_path, [5], start=Pose2D(1.5, 2.6, 0.0))
    assert _outcomes(run) == ["success"], run.out
    found = run.events("search_found")
    assert len(found) == 1
    assert found[0]["locations"] == 0 and 2 <= found[0]["views"] <= 12  # turning in place was enough
    _assert_delivered(run, 1, "box_5")
    assert _at_home(run, 1)


def test_item_at_the_second_search_location(tmp_path: Path) -> None:
    # the far shelf cannot be read from home nor from in front of the near shelf
    locations = [[1.5, 2.5, 3.14159], [3.0, 2.0, 0.0]]
    run = run_fetch(tmp_path, [3], params={"search_locations": locations})
    assert _outcomes(run) == ["success"], run.out
    found = run.events("search_found")
    assert len(found) == 1
    assert found[0]["locations"] == 2
    assert found[0]["views"] == 25  # a full turn (12 views) at home and at location 1, then the first view
    _assert_delivered(run, 1, "box_3")


def _fail_picks(fail_in_requests: set[int], per_request: int | None):
    """A setup hook: the sim's fault injector fails the first arm goal of each `pick`
    (its pre-grasp motion) in the given requests, at most ``per_request`` times per
    request (None: every pick). Other arm goals (stow, home) are spared, so the give-up
    path can run."""
    state = {"request": 0, "armed": False, "failed": 0}

    def setup(robot: Any, runner: Runner) -> None:
        inj = robot.injector
        original = inj.arm_attempt_fails

        def listener(record: dict[str, Any]) -> None:
            ev = record.get("event")
            if ev == "request_start":
                state["request"] += 1
                state["failed"] = 0
            elif ev == "skill_start" and record.get("skill") == "pick":
                limit_ok = per_request is None or state["failed"] < per_request
                state["armed"] = state["request"] in fail_in_requests and limit_ok

        def arm_attempt_fails(now: float) -> bool:
            if state["armed"]:
                state["armed"] = False
                state["failed"] += 1
                inj.arm_attempts += 1
                inj.fired.append((now, f"arm_fail attempt {inj.arm_attempts} (pick, request {state['request']})"))
                return True
            return original(now)

        inj.arm_attempt_fails = arm_attempt_fails
        runner.log.add_listener(listener)

    return setup


def test_arm_failure_once_recovers_with_one_recovery(tmp_path: Path) -> None:
    run = run_fetch(tmp_path, [3], start=FACING_FAR_SHELF, setup=_fail_picks({1}, 1))
    assert _outcomes(run) == ["success"], run.out
    case1 = run.recoveries("fetch_item/pick_item")
    assert len(case1) == 1 and run.results[0].recoveries == 1
    assert "pre-grasp" in case1[0]["reason"]
    assert not run.events("recovery_give_up")
    # the recovery went home and searched again before the second pick
    assert len(_skills_started(run, "pick")) == 2
    assert [f for _, f in run.truth[0].faults_fired if "arm_fail" in f] != []
    _assert_delivered(run, 1, "box_3")


def test_arm_failure_always_gives_up_after_two_recoveries_and_serves_the_next(tmp_path: Path) -> None:
    run = run_fetch(tmp_path, [3, 5], start=FACING_FAR_SHELF, setup=_fail_picks({1}, None))
    assert _outcomes(run) == ["failure", "success"], run.out
    case1 = run.recoveries("fetch_item/pick_item", request=1)
    assert len(case1) == 2 and run.results[0].recoveries == 2
    give_up = run.events("recovery_give_up", request=1)
    assert [g["node"] for g in give_up] == ["fetch_item/pick_item"]
    assert len(_skills_started(run, "pick", request=1)) == 3
    assert "not fetched" in run.out
    assert _at_home(run, 1) and run.truth[0].held is None and "box_3" not in run.truth[0].in_depot
    # the next request is served normally
    assert run.results[1].recoveries == 0
    _assert_delivered(run, 2, "box_5")
    assert run.exit_code == 1


def test_blocked_standoff_uses_the_approach_distance_recovery(tmp_path: Path) -> None:
    run = run_fetch(tmp_path, [3, 5], start=FACING_FAR_SHELF, faults="{nav_blocked: [box_3]}")
    assert _outcomes(run) == ["failure", "success"], run.out
    case2 = run.recoveries("/approach", request=1)
    assert len(case2) == 2
    # each attempt asked for the next distance of the profile's list, found no free
    # stand-off, and the holistic planner (the approach's fallback) found no base pose in
    # the blocked area either: its failure is the attempt's reason
    assert all(r["reason"].startswith("holistic plan: no base pose") for r in case2)
    approaches = [r for r in run.events("skill_failure", request=1) if r.get("skill") == "approach"]
    assert len(approaches) == 3 and all(r["kind"] == "planning" and "no free stand-off" in r["reason"] for r in approaches)
    holistic = [r for r in run.events("skill_failure", request=1) if r.get("skill") == "holistic_standoff"]
    assert len(holistic) == 3 and all(r["kind"] == "planning" for r in holistic)
    assert [g["node"].rsplit("/", 1)[-1] for g in run.events("recovery_give_up", request=1)] == ["approach"]
    # a reset, not an arm failure: no pick was tried, and case 1's recovery declined at
    # once (its condition sees approach.outcome == gave_up) instead of searching again
    assert _skills_started(run, "pick", request=1) == []
    assert len(run.recoveries("fetch_item/pick_item", request=1)) == 1
    assert [r["node"] for r in run.events("recovery_failed", request=1)] == ["fetch_item/pick_item"]
    assert len(_skills_started(run, "detect_marker", request=1)) == 1
    assert _at_home(run, 1)
    _assert_delivered(run, 2, "box_5")
    assert math.isfinite(run.results[0].duration)


def test_arm_failing_before_the_approach_ran_is_recovered(tmp_path: Path) -> None:
    """The first arm goal of the run (the look pose, before any approach) fails: case 1
    still recovers (its guard treats "approach never ran" as "approach did not give up")."""
    run = run_fetch(tmp_path, [3], start=FACING_FAR_SHELF, faults="{arm_fail_attempts: [1]}")
    assert _outcomes(run) == ["success"], run.out
    case1 = run.recoveries("fetch_item/pick_item")
    assert len(case1) == 1 and run.results[0].recoveries == 1, run.out
    assert _skills_started(run, "approach", request=1)[0]["t"] >= case1[0]["t"]  # failed before approaching
    assert [f for _, f in run.truth[0].faults_fired if "arm_fail" in f] != []
    _assert_delivered(run, 1, "box_3")
