"""pick and place logic on the mock backend, no physics: the planning-scene sequence
(add on perception, attach on grasp, detach + remove on place), the held-item world-model
key, arm states, and failures from a scripted gripper or arm. Motions are planned for
real (OMPL against the WX250s planning model) and followed by the mock arm."""

from __future__ import annotations

import math

import numpy as np
import pytest
from fetchkit import events_of, marker_pose, run_skill

from mmexec.drivers.interfaces import GraspState, Pose2D
from mmexec.drivers.mock.robot import MockArm, MockGripper
from mmexec.skills.base import FailureKind, SkillStatus
from mmexec.skills.manipulation import wx250s
from mmexec.skills.manipulation.arm import WORLD_ARM, WORLD_HELD
from mmexec.skills.perception.detect import WORLD_MARKERS, MarkerEstimate


@pytest.fixture
def arm_robot(fetch_robot):
    """The fetch mock robot with a WX250s-jointed mock arm (at the profile's tuck pose)
    and a gripper whose first close meets a 50 mm item and whose later closes meet
    nothing (place's close after its retract: the released item stayed in the basket)."""
    kin = wx250s(locobot=True)
    fetch_robot.arm = MockArm(fetch_robot.clock, limits=kin.limits,
                              start=fetch_robot.profile["named_poses"]["tuck"])
    fetch_robot.gripper = MockGripper(fetch_robot.clock, grasps=[True], default_grasp=False, object_width=0.05)
    return fetch_robot


def _perceive(ctx, robot, marker: int = 7) -> None:
    """An estimate of ``marker`` 0.40 m ahead of the arm base, 0.20 m up, facing it."""
    p = robot.base.pose
    T = marker_pose(p.x + 0.40, p.y, 0.20, math.pi)
    ctx.world.setdefault(WORLD_MARKERS, {})[marker] = MarkerEstimate(marker, T, 3, 0.0, 0.5)


def _scene_ops(ctx) -> list[str]:
    return [e["op"] for e in events_of(ctx, "scene_update")]


def test_pick_then_place_runs_the_seed_scene_sequence(arm_robot, fetch_ctx):
    _perceive(fetch_ctx, arm_robot)
    start = arm_robot.base.pose
    run = run_skill(fetch_ctx, "pick", {"marker": 7})
    assert run.status is SkillStatus.SUCCESS, run.failure
    assert run.outputs == {"item": "item_7"}
    assert _scene_ops(fetch_ctx) == ["add", "attach"]
    ws = fetch_ctx.world[WORLD_ARM]
    assert set(ws.scene.items) == {"item_7"} and ws.scene.items["item_7"].attached
    assert fetch_ctx.world[WORLD_HELD] == "item_7"
    gs = arm_robot.gripper.state()
    assert gs.grasp is GraspState.CONTACT_CLOSING and gs.width == pytest.approx(0.05)
    # backed off the shelf (profile back_off 0.1 m) and ended in the carry pose
    assert start.distance_to(arm_robot.base.pose) == pytest.approx(0.1, abs=0.01)
    assert list(arm_robot.arm.state().positions) == pytest.approx(arm_robot.profile["named_poses"]["carry"], abs=0.02)
    assert [e["status"] for e in events_of(fetch_ctx, "arm_status")] == ["running", "success", "idle"]
    planned = [e["what"] for e in events_of(fetch_ctx, "arm_plan")]
    assert planned[:3] == ["pre-grasp", "grasp approach", "retract"] and planned[-1] == "arm to carry"

    # at the depot: place opens, detaches and removes the item, retracts, closes (on
    # nothing: the item stayed in the basket), stows
    arm_robot.base.pose = Pose2D(1.0, 4.0, math.pi / 2)
    fetch_ctx.events.clear()
    run = run_skill(fetch_ctx, "place")
    assert run.status is SkillStatus.SUCCESS, run.failure
    assert run.outputs == {"item": "item_7"}
    assert _scene_ops(fetch_ctx) == ["detach_remove"]
    assert ws.scene.items == {} and WORLD_HELD not in fetch_ctx.world
    assert list(arm_robot.arm.state().positions) == pytest.approx(arm_robot.profile["named_poses"]["tuck"], abs=0.02)
    assert [e["what"] for e in events_of(fetch_ctx, "arm_plan")] == ["place pose", "place retract", "arm to tuck"]
    # the item was let go and not taken again: the fingers closed fully, on nothing
    gs = arm_robot.gripper.state()
    assert gs.grasp is GraspState.AT_POSITION and gs.width == pytest.approx(arm_robot.gripper.min_width)
    assert arm_robot.gripper.closes == 2 and not events_of(fetch_ctx, "place_item_caught")


def _pick_and_go_to_depot(ctx, robot) -> None:
    _perceive(ctx, robot)
    assert run_skill(ctx, "pick", {"marker": 7}).status is SkillStatus.SUCCESS
    robot.base.pose = Pose2D(1.0, 4.0, math.pi / 2)
    ctx.events.clear()


def test_place_lets_go_again_when_the_released_item_came_along(arm_robot, fetch_ctx):
    """The close after the retract meets the item (it caught on the fingers and rose with
    them: the UR5e's screwdriver hanging from a pad by its handle): place takes it back
    down turned half a turn, opens, retracts and closes again, on nothing now; it never
    stows holding the item."""
    from mmexec.skills.fetch.arm import _rolled

    arm_robot.gripper.grasps = [True, True]  # pick; the first close after the release
    _pick_and_go_to_depot(fetch_ctx, arm_robot)
    followed = []
    follow = arm_robot.arm.follow
    arm_robot.arm.follow = lambda trajectory: followed.append(trajectory) or follow(trajectory)
    run = run_skill(fetch_ctx, "place")
    assert run.status is SkillStatus.SUCCESS, run.failure
    caught = events_of(fetch_ctx, "place_item_caught")
    assert [(e["item"], e["release"], e["width"]) for e in caught] == [("item_7", 1, 0.05)]
    plans = [e["what"] for e in events_of(fetch_ctx, "arm_plan")]
    assert plans == ["place pose", "place retract", "place again", "place retract", "arm to tuck"]
    assert arm_robot.gripper.closes == 3  # the pick's, the one that met the item, the one on nothing
    gs = arm_robot.gripper.state()
    assert gs.grasp is GraspState.AT_POSITION and gs.width == pytest.approx(arm_robot.gripper.min_width)
    assert WORLD_HELD not in fetch_ctx.world
    # the second release was half a turn about the approach axis from the first
    kin = fetch_ctx.world[WORLD_ARM].kin
    T0, T = (np.asarray(kin.fk(followed[i].positions[-1])) for i in (0, 2))  # ends of "place pose", "place again"
    assert T[:3, :3] == pytest.approx(_rolled(T0, kin.approach_axis, math.pi)[:3, :3], abs=0.02)
    assert T[:3, 3] == pytest.approx(T0[:3, 3], abs=0.01)


def test_place_fails_holding_an_item_that_will_not_let_go(arm_robot, fetch_ctx):
    """Every close after a release meets the item: after PLACE_RELEASES releases place
    fails POSTCONDITION with the item held (the world model says so), not stowed and not
    reported as delivered."""
    from mmexec.skills.fetch.arm import PLACE_RELEASES

    arm_robot.gripper.default_grasp = True
    _pick_and_go_to_depot(fetch_ctx, arm_robot)
    run = run_skill(fetch_ctx, "place")
    assert run.status is SkillStatus.FAILURE and run.failure.kind is FailureKind.POSTCONDITION
    assert run.failure.reason == (f"place: item_7 still in the gripper after {PLACE_RELEASES} releases "
                                  "(it closed on it at 50 mm)")
    assert [e["release"] for e in events_of(fetch_ctx, "place_item_caught")] == list(range(1, PLACE_RELEASES + 1))
    assert fetch_ctx.world[WORLD_HELD] == "item_7"
    assert arm_robot.gripper.state().grasp is GraspState.CONTACT_CLOSING
    assert "arm to tuck" not in [e["what"] for e in events_of(fetch_ctx, "arm_plan")]


def test_pick_closing_on_nothing_fails_postcondition_and_clears_the_scene(arm_robot, fetch_ctx):
    arm_robot.gripper.grasps = [False]
    _perceive(fetch_ctx, arm_robot)
    run = run_skill(fetch_ctx, "pick", {"marker": 7})
    assert run.status is SkillStatus.FAILURE
    assert run.failure.kind is FailureKind.POSTCONDITION
    assert run.failure.reason.startswith("nothing held after closing on marker 7")
    assert _scene_ops(fetch_ctx) == ["add"]  # never attached
    assert fetch_ctx.world[WORLD_ARM].scene.items == {}
    assert WORLD_HELD not in fetch_ctx.world
    assert arm_robot.gripper.state().width == pytest.approx(arm_robot.gripper.max_width)  # released
    arm = events_of(fetch_ctx, "arm_status")
    assert [e["status"] for e in arm] == ["running", "fail", "idle"]
    assert arm[1]["kind"] == "postcondition"


def test_pick_arm_failure_is_execution_and_leaves_nothing_attached(arm_robot, fetch_ctx):
    arm_robot.arm.fail_moves = {1}
    _perceive(fetch_ctx, arm_robot)
    run = run_skill(fetch_ctx, "pick", {"marker": 7})
    assert run.status is SkillStatus.FAILURE
    assert run.failure.kind is FailureKind.EXECUTION
    assert run.failure.reason.startswith("pre-grasp: ") and "scripted" in run.failure.reason
    assert fetch_ctx.world[WORLD_ARM].scene.items == {}
    assert arm_robot.gripper.closes == 0


def test_pick_without_an_estimate_and_place_without_an_item(arm_robot, fetch_ctx):
    run = run_skill(fetch_ctx, "pick", {"marker": 7})
    assert run.failure.kind is FailureKind.PRECONDITION and "detect it first" in run.failure.reason
    run = run_skill(fetch_ctx, "place")
    assert run.failure.kind is FailureKind.PRECONDITION and run.failure.reason.startswith("place: nothing held")


def test_pick_out_of_reach_is_a_planning_failure(arm_robot, fetch_ctx):
    p = arm_robot.base.pose
    fetch_ctx.world[WORLD_MARKERS] = {7: MarkerEstimate(7, marker_pose(p.x + 1.5, p.y, 0.15, math.pi), 3, 0.0, 1.5)}
    run = run_skill(fetch_ctx, "pick", {"marker": 7})
    assert run.status is SkillStatus.FAILURE
    assert run.failure.kind is FailureKind.PLANNING and run.failure.reason.startswith("pre-grasp: ")
    assert arm_robot.arm.moves == 0


def test_place_releases_higher_when_the_nominal_pose_is_blocked(arm_robot, fetch_ctx):
    """A slab where the held item would be released at the nominal place pose (profile
    depot.place = (1.0, 4.45, 0.25)): place plans the next height of PLACE_RAISES instead
    of failing, and says so in the log."""
    import numpy as np

    from mmexec.drivers.interfaces import SceneBox
    from mmexec.skills.fetch.arm import PLACE_RAISES

    _perceive(fetch_ctx, arm_robot)
    assert run_skill(fetch_ctx, "pick", {"marker": 7}).status is SkillStatus.SUCCESS
    arm_robot.base.pose = Pose2D(1.0, 4.0, math.pi / 2)
    T = np.eye(4)
    T[:3, 3] = (1.0, 4.45, 0.25)
    arm_robot.scene = [*arm_robot.scene, SceneBox("slab", T, (0.10, 0.10, 0.02))]
    fetch_ctx.events.clear()
    run = run_skill(fetch_ctx, "place")
    assert run.status is SkillStatus.SUCCESS, run.failure
    raised = events_of(fetch_ctx, "place_raised")
    assert len(raised) == 1 and raised[0]["by"] in PLACE_RAISES[1:]


def test_place_fails_planning_when_every_release_height_is_blocked(arm_robot, fetch_ctx):
    import numpy as np

    from mmexec.drivers.interfaces import SceneBox
    from mmexec.skills.fetch.arm import PLACE_RAISES

    _perceive(fetch_ctx, arm_robot)
    assert run_skill(fetch_ctx, "pick", {"marker": 7}).status is SkillStatus.SUCCESS
    arm_robot.base.pose = Pose2D(1.0, 4.0, math.pi / 2)
    T = np.eye(4)
    T[:3, 3] = (1.0, 4.45, 0.25 + PLACE_RAISES[-1] / 2)
    arm_robot.scene = [*arm_robot.scene, SceneBox("column", T, (0.10, 0.10, PLACE_RAISES[-1] + 0.10))]
    run = run_skill(fetch_ctx, "place")
    assert run.status is SkillStatus.FAILURE and run.failure.kind is FailureKind.PLANNING
    assert run.failure.reason.startswith("place pose:"), run.failure.reason
    assert not events_of(fetch_ctx, "place_raised")


@pytest.mark.parametrize("closer", [0.05, 0.11])
def test_place_retracts_up_when_the_base_stopped_short_of_the_depot_pose(arm_robot, fetch_ctx, closer):
    """The base stopped ``closer`` [m] nearer the basket than its depot pose (the LoCoBot
    lab crowd row's trials 107 and 132: docked 6 cm short): from the release pose the
    profile's retract, straight back towards the base, folds the upper arm into the camera
    tower. Place retracts another way (straight up, or up and out over the basket), which
    leaves the released item all the same, closes on nothing and stows."""
    from mmexec.skills.fetch.arm import RETRACT_WAYS

    _perceive(fetch_ctx, arm_robot)
    assert run_skill(fetch_ctx, "pick", {"marker": 7}).status is SkillStatus.SUCCESS
    arm_robot.base.pose = Pose2D(1.0, 4.0 + closer, math.pi / 2)
    fetch_ctx.events.clear()
    followed = []
    follow = arm_robot.arm.follow
    arm_robot.arm.follow = lambda trajectory: followed.append(trajectory) or follow(trajectory)
    run = run_skill(fetch_ctx, "place")
    assert run.status is SkillStatus.SUCCESS, run.failure
    assert [e["what"] for e in events_of(fetch_ctx, "arm_plan")] == ["place pose", "place retract", "arm to tuck"]
    ways = [e["way"] for e in events_of(fetch_ctx, "place_retract_changed")]
    assert len(ways) == 1 and ways[0] in RETRACT_WAYS
    ws = fetch_ctx.world[WORLD_ARM]
    T_release, T_out = (np.asarray(ws.kin.fk(followed[i].positions[-1])) for i in (0, 1))
    # the profile's straight retract from that release pose is in collision with the robot
    nominal = T_release.copy()
    nominal[:3, 3] += _towards_base(T_release, 0.1)
    assert not ws.planner.cartesian_path(list(followed[0].positions[-1]), nominal).success
    rise = T_out[:3, 3] - T_release[:3, 3]
    assert rise[2] == pytest.approx(0.1, abs=0.01)  # up by the profile retract's length (fetch.place_retract)
    assert np.hypot(*T_release[:2, 3]) <= np.hypot(*T_out[:2, 3]) + 0.005  # not back towards the arm base
    assert arm_robot.gripper.closes == 2 and WORLD_HELD not in fetch_ctx.world
    assert list(arm_robot.arm.state().positions) == pytest.approx(arm_robot.profile["named_poses"]["tuck"], abs=0.02)


def _towards_base(T_tool: np.ndarray, length: float) -> np.ndarray:
    """``length`` [m] horizontally from the tool at ``T_tool`` (arm base frame) towards
    the arm base: the profile's place retract (fetch.place_retract, along the place
    frame's z, which points at the base)."""
    d = -np.asarray(T_tool[:2, 3], dtype=float)
    return np.array([*(length * d / np.linalg.norm(d)), 0.0])
