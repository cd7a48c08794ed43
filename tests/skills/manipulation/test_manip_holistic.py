"""The holistic base + arm planner (skills/manipulation/holistic.py): the 9-D model's joints
and bounds, its validity (footprint in the inflated map, the robot in the planning scene),
a blocked-front query solved, unsolvable ones failing with a clear reason, and the batched
IK it samples goals with."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mmexec.drivers.descriptions import get
from mmexec.drivers.interfaces import Pose2D
from mmexec.sim.world import Obstacle, load_world
from mmexec.skills.manipulation.batch_ik import batch_fk, batch_ik
from mmexec.skills.manipulation.grasp import grasp_poses
from mmexec.skills.manipulation.holistic import (
    BASE_JOINTS,
    HolisticConfig,
    HolisticModel,
    HolisticPlanner,
    armbase_in_map,
    replan_arm,
)
from mmexec.skills.manipulation.kinematics import ur5e, wx250s
from mmexec.skills.navigation.astar import plan_path
from mmexec.skills.navigation.grid import inflate
from mmexec.skills.navigation.standoff import find_standoff

DESC = get("locobot_wx250s")
TUCK = (0.0, -0.4, 1.1, 0.0, 1.4, 0.0)  # config/locobot_sim.yaml's stow pose
HOME = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)   # its reach pose: stretched forward


def _marker_frame(world, item: str) -> np.ndarray:
    """The marker frame (z out of the item's +x face, y up) of a world item, in map."""
    T_item = world.item_poses[item]
    x = T_item[:3, 0]
    T = np.eye(4)
    T[:3, 2], T[:3, 1] = x, (0.0, 0.0, 1.0)
    T[:3, 0] = np.cross(T[:3, 1], T[:3, 2])
    T[:3, 3] = T_item[:3, 3] + x * world.item(item).size[0] / 2
    return T


@pytest.fixture(scope="module")
def lab():
    """The lab with a 0.2 m high box on the floor in front of box_1 (far shelf, lower
    board): no stand-off of the LoCoBot's approach distances is free."""
    T_marker = _marker_frame(load_world("lab"), "box_1")
    n = T_marker[:3, 2]
    c = T_marker[:3, 3] + 0.32 * n
    blocker = Obstacle("blocker", (float(c[0]), float(c[1]), math.atan2(n[1], n[0])), (0.3, 0.4, 0.2))
    world = load_world("lab", extra_obstacles=(blocker,))
    cm = inflate(world.occupancy(0.05), DESC.info.footprint_radius, 0.03)
    return world, cm, T_marker


@pytest.fixture(scope="module")
def model(lab):
    world, cm, _ = lab
    m = HolisticModel.build(DESC, cm)
    m.prepare(world.scene_boxes())
    yield m
    m.close()


def test_model_joints_and_bounds(model, lab):
    _, _cm, T_marker = lab
    assert model.joint_names == BASE_JOINTS + DESC.info.arm_joints
    assert model.dof == 9
    planner = HolisticPlanner(model, HolisticConfig(box=1.0))
    start = Pose2D(2.5, 2.0, 0.5)
    lo, hi = planner.bounds(start)
    assert lo[:2] == pytest.approx([1.5, 1.0]) and hi[:2] == pytest.approx([3.5, 3.0])
    assert (lo[2], hi[2]) == pytest.approx((0.5 - math.pi, 0.5 + math.pi))
    assert np.allclose(np.stack([lo[3:], hi[3:]], 1), model.scene.limits)
    # widened to hold the target's surroundings, clipped to the map (origin at the wall's outside)
    lo, hi = planner.bounds(start, T_marker[:3, 3])
    assert hi[0] == pytest.approx(5.1) and lo[0] == pytest.approx(1.5)
    assert hi[0] > T_marker[0, 3]
    # the tool pose of a state is the base pose, the mount and the arm's FK
    state = (1.0, 2.0, math.pi / 2, *TUCK)
    T = armbase_in_map(Pose2D(1.0, 2.0, math.pi / 2), DESC.arm_mount) @ model.kin.fk(TUCK)
    assert np.allclose(model.tool_pose(state), T)
    assert T[0, 3] == pytest.approx(1.0, abs=0.05) and T[1, 3] > 2.0  # in front of the base, which faces +y


def test_validity(model, lab):
    world, _cm, _ = lab
    # the base's footprint on the blocker in front of the far shelf: invalid whatever the arm does
    blocker = next(o for o in world.obstacles if o.name == "blocker")
    on_blocker = (blocker.pose[0], blocker.pose[1], 0.0, *TUCK)
    assert not model.footprint_free(np.array([blocker.pose[0]]), np.array([blocker.pose[1]]))[0]
    assert not model.is_valid(on_blocker)
    assert ("base footprint", "map") in model.collisions(on_blocker)
    # free footprint, arm stretched into the south wall (the base 0.45 m from it, facing it)
    into_wall = (1.2, 0.45, -math.pi / 2, *HOME)
    assert model.footprint_free(np.array([1.2]), np.array([0.45]))[0]
    assert not model.is_valid(into_wall)
    assert any(b == "wall_south" for _, b in model.collisions(into_wall))
    # the same base pose with the arm tucked: valid; off the map: invalid
    assert model.is_valid((1.2, 0.45, -math.pi / 2, *TUCK))
    assert not model.is_valid((-1.0, 2.0, 0.0, *TUCK))
    # arrays: footprint and the start's free region
    xs, ys = np.array([1.2, blocker.pose[0], 8.0]), np.array([0.45, blocker.pose[1], 2.0])
    assert model.footprint_free(xs, ys).tolist() == [True, False, False]
    regions = model.regions(xs, ys)
    assert regions[0] == model.region(2.5, 2.0) > 0 and regions[1] == regions[2] == 0


def test_blocked_front_query_solved(model, lab):
    world, cm, T_marker = lab
    assert not find_standoff(cm, T_marker, [0.35, 0.45, 0.55]).ok  # the premise: the front is blocked
    poses = grasp_poses(T_marker, model.kin.approach_axis, pre_grasp=(0.0, 0.0, 0.10), grasp_depth=0.03)
    start = Pose2D(2.5, 2.0, 0.0)
    planner = HolisticPlanner(model, HolisticConfig(seed=3))
    res = planner.plan(start, TUCK, poses.pre_grasp, T_map_grasp=poses.grasp, seeds=[HOME])
    assert res.success, res.reason
    assert res.base_pose is not None and res.arm is not None
    b = res.base_pose
    # the base pose is free in the inflated map and A* gets there from the start
    assert cm.is_free(b.x, b.y)
    assert plan_path(cm, (start.x, start.y), (b.x, b.y)) is not None
    # the arm reaches the pre-grasp from there (PoE forward kinematics), collision-free, stow too
    state = (b.x, b.y, b.theta, *res.arm)
    T = armbase_in_map(b, DESC.arm_mount) @ wx250s().fk(res.arm)
    assert np.linalg.norm(T[:3, 3] - poses.pre_grasp[:3, 3]) < 1e-3
    assert np.allclose(T[:3, :3], poses.pre_grasp[:3, :3], atol=1e-2)
    assert model.is_valid(state)
    assert model.arm_valid(b.x, b.y, b.theta, TUCK)
    # the stowed arm stays free with the base anywhere within the drive margin of the goal
    assert planner.drive_clear(b.x, b.y, b.theta, TUCK, planner.config.drive_margin)
    # the straight pre-grasp -> grasp line has IK without jumps, as the pick will move it
    T_am = np.linalg.inv(armbase_in_map(b, DESC.arm_mount))
    model.arm_valid(b.x, b.y, b.theta, res.arm)
    qg = planner._approach(T_am @ poses.pre_grasp, T_am @ poses.grasp, np.asarray(res.arm), False)
    assert qg is not None
    assert np.linalg.norm(wx250s().fk(qg)[:3, 3] - (T_am @ poses.grasp)[:3, 3]) < 1e-3
    # the 9-D path starts at the start and ends at the goal, every state valid
    assert res.path[0][:3] == pytest.approx((start.x, start.y, start.theta))
    assert res.path[-1] == pytest.approx(state)
    assert all(model.is_valid(s) for s in res.path[1:])
    # not in front of the blocker: beside it or behind it
    assert not any(math.dist((b.x, b.y), (p.x, p.y)) < 0.05
                   for p in [find_standoff(inflate(load_world("lab").occupancy(0.05), 0.178, 0.03), T_marker,
                                           [d]).pose for d in (0.35, 0.45, 0.55)] if p is not None)
    # a start a little inside the inflation by the south wall (the body clear of it) leaves it
    near_wall = Pose2D(1.5, 0.19, 0.0)
    assert not cm.is_free(near_wall.x, near_wall.y)
    res = planner.plan(near_wall, TUCK, poses.pre_grasp, T_map_grasp=poses.grasp, seeds=[HOME])
    assert res.success, res.reason
    assert model.exempt is None
    model.release()
    model.prepare(world.scene_boxes())


def test_unsolvable_queries_fail_with_a_reason(model, lab):
    world, _cm, T_marker = lab
    planner = HolisticPlanner(model, HolisticConfig(attempts=2, goal_candidates=100))
    # a pre-grasp 1.6 m up: no base pose brings the arm there
    T = np.array(T_marker)
    T[2, 3] = 1.6
    res = planner.plan(Pose2D(2.5, 2.0, 0.0), TUCK, T, seeds=[HOME])
    assert not res.success and res.base_pose is None
    assert res.reason.startswith("no base pose within reach of the pre-grasp at (4.6")
    assert "had an IK" in res.reason and res.attempts == 2
    # a start on the blocker
    blocker = next(o for o in world.obstacles if o.name == "blocker")
    res = planner.plan(Pose2D(blocker.pose[0], blocker.pose[1], 0.0), TUCK, T_marker)
    assert not res.success and "blocked in the inflated map" in res.reason
    # cancelled before it starts
    planner.stop.set()
    res = planner.plan(Pose2D(2.5, 2.0, 0.0), TUCK, T_marker)
    planner.stop.clear()
    assert not res.success and res.reason == "cancelled"
    model.release()
    model.prepare(world.scene_boxes())


def test_drive_margin_keeps_the_stowed_arm_off_the_wall(model):
    """drive_clear: the stowed arm free at the pose is not enough when the base may stop
    6 cm closer to the wall; farther out it is clear all round; (0, 0) checks the pose only."""
    planner = HolisticPlanner(model)
    x, yaw = 1.2, -math.pi / 2  # facing the south wall
    ys = np.arange(0.60, 0.05, -0.005)
    y0 = next(float(y) for y in ys if not model.arm_valid(x, float(y), yaw, TUCK)) + 0.005  # the last free one
    assert model.arm_valid(x, y0, yaw, TUCK)
    assert planner.drive_clear(x, y0, yaw, TUCK, (0.0, 0.0))
    assert not planner.drive_clear(x, y0, yaw, TUCK, (0.06, 0.06))
    assert not planner.drive_clear(x, y0 + 0.04, yaw, TUCK, (0.06, 0.0))
    assert planner.drive_clear(x, y0 + 0.07, yaw, TUCK, (0.06, 0.06))
    model.release()


def test_back_off_distance(lab):
    """Straight back as far as the inflated map stays free; from a pose inside the
    inflation only out of it (10 cm blind at most), never further in."""
    from mmexec.skills.manipulation.holistic import back_off_distance

    _world, cm, _ = lab
    assert back_off_distance(cm, Pose2D(2.5, 2.0, 0.0), 0.3) == pytest.approx(0.3)
    # facing north 0.45 m from the south wall: backing towards it stops at the inflation
    d = back_off_distance(cm, Pose2D(1.2, 0.45, math.pi / 2), 0.3)
    assert 0.1 < d < 0.25 and cm.is_free(1.2, 0.45 - d) and not cm.is_free(1.2, 0.45 - d - 0.05)
    # inside the inflation by the wall: facing it, backing out is allowed; facing away, nothing
    assert not cm.is_free(1.2, 0.19)
    assert back_off_distance(cm, Pose2D(1.2, 0.19, -math.pi / 2), 0.3) == pytest.approx(0.3)
    assert back_off_distance(cm, Pose2D(1.2, 0.19, math.pi / 2), 0.3) == 0.0


def test_the_carried_object_must_clear_a_low_blocker(model, lab):
    """A goal facing the 0.2 m blocker holds the carried box (8 cm high) on it in the carry
    posture; turned away the same base position is clear; without the object it is clear."""
    world, _cm, T_marker = lab
    planner = HolisticPlanner(model)
    blocker = next(o for o in world.obstacles if o.name == "blocker")
    n = T_marker[:3, 2]
    bx, by = blocker.pose[0] + 0.45 * n[0], blocker.pose[1] + 0.45 * n[1]
    facing = math.atan2(-n[1], -n[0])
    carry = np.array([0.0, -0.2, 0.6, 0.0, 0.5, 0.0])  # config/locobot_sim.yaml's carry pose
    q_grasp = np.array(HOME)
    model.arm_valid(bx, by, facing, q_grasp)
    T_grasp = model.tool_pose((bx, by, facing, *q_grasp))
    cfg = HolisticConfig(drive_margin=(0.0, 0.0))
    try:
        planner._carry = (carry, (0.05, 0.08, 0.05), 0.0)
        assert planner.drive_clear(bx, by, facing, carry, (0.0, 0.0))  # the arm alone clears it
        assert not planner._carry_clear(bx, by, facing, q_grasp, T_grasp, cfg)
        away = facing + math.pi
        model.arm_valid(bx, by, away, q_grasp)
        assert planner._carry_clear(bx, by, away, q_grasp, model.tool_pose((bx, by, away, *q_grasp)), cfg)
        assert "holistic_carried" not in model.scene.items
    finally:
        planner._carry = None
        model.release()
        model.prepare(world.scene_boxes())


def test_replan_arm_escapes_a_start_a_little_in_collision():
    """The measured stow posture a few hundredths of a rad off (the tuck's open fingers
    into the arm base link) is left by a short move to the stow posture when that is free;
    farther off, or without the stow posture, it stays a start in collision."""
    from mmexec.skills.manipulation.planner import ArmPlanner, PlannerConfig
    from mmexec.skills.manipulation.scene import ArmModel, PlanningScene

    with PlanningScene(ArmModel.from_description(DESC)) as scene:
        arm = ArmPlanner(scene, wx250s(), PlannerConfig(seed=0))
        reached = Pose2D(2.0, 2.0, 0.0)
        T_pre = armbase_in_map(reached, DESC.arm_mount) @ wx250s().fk((0.0, 0.2, 0.2, 0.0, 0.6, 0.0))
        off = np.array(TUCK)
        off[1] += 0.04  # shoulder: the fingers into the arm base link
        assert not scene.is_valid(off) and scene.is_valid(TUCK)
        plain = replan_arm(arm, reached, DESC.arm_mount, off, T_pre, [])
        assert not plain.success and plain.reason.startswith("start in collision")
        res = replan_arm(arm, reached, DESC.arm_mount, off, T_pre, [], q_escape=TUCK)
        assert res.success, res.reason
        assert res.path[0] == pytest.approx(tuple(off)) and res.path[1] == pytest.approx(TUCK)
        traj = res.trajectory
        assert traj is not None and traj.positions[-1] == pytest.approx(res.path[-1])
        assert any(np.allclose(p, TUCK, atol=1e-6) for p in traj.positions)  # through the stow posture
        far = np.array(TUCK)
        far[1] += 0.10
        assert not scene.is_valid(far)
        res = replan_arm(arm, reached, DESC.arm_mount, far, T_pre, [], q_escape=TUCK)
        assert not res.success and res.reason.startswith("start in collision")


@pytest.mark.parametrize("kin", [wx250s(), ur5e()], ids=["wx250s", "ur5e"])
def test_batch_ik_matches_the_arm(kin):
    rng = np.random.default_rng(1)
    Q = rng.uniform(np.maximum(kin.lower, -3.0), np.minimum(kin.upper, 3.0), (40, kin.dof))
    R, p, J = batch_fk(kin, Q)
    for k in range(40):
        T, Js = kin.fk_and_jacobian(Q[k])
        assert np.allclose(R[k], T[:3, :3]) and np.allclose(p[k], T[:3, 3]) and np.allclose(J[k], Js)
    targets = np.stack([kin.fk(q) for q in Q])
    starts = np.clip(Q + rng.normal(0.0, 0.4, Q.shape), kin.lower, kin.upper)
    for free in (False, True):
        q, ok = batch_ik(kin, targets, starts, free_approach_rotation=free)
        assert ok.sum() >= 36
        for k in np.flatnonzero(ok):
            T = kin.fk(q[k])
            assert np.linalg.norm(T[:3, 3] - targets[k][:3, 3]) < 1e-3
            a = kin.approach_axis
            assert float(T[:3, a] @ targets[k][:3, a]) > 0.999
            assert kin.within_limits(q[k])
    # a target beyond the reach never converges
    far = targets[:1].copy()
    far[0, :3, 3] = (3.0, 0.0, 0.0)
    assert not batch_ik(kin, far, starts[:1])[1][0]


def test_holistic_standoff_skill_on_the_mock(mock_robot, run_mock_skill, skill_ctx, lab):
    """The skill plans, drives the mock base there (A* + tracking on the lab map with the
    blocker), re-plans the arm from the pose reached and moves it to the pre-grasp."""
    from mmexec.skills.base import SkillStatus
    from mmexec.skills.manipulation.arm import close_workspace
    from mmexec.skills.manipulation.holistic_skill import grasp_frame  # registers the skill

    world, _, T_marker = lab
    mock_robot.occupancy = world.occupancy(0.05)
    mock_robot.scene = tuple(world.scene_boxes())
    mock_robot.base.pose = Pose2D(2.5, 2.0, 0.0)
    mock_robot.profile["named_poses"]["tuck"] = list(TUCK)
    mock_robot.profile["arm"] = {"stow": "tuck", "reach": "home"}
    point = (T_marker[:3, 3] - 0.03 * T_marker[:3, 2]).tolist()  # the box's centre, 3 cm behind its face
    yaw = math.atan2(T_marker[1, 2], T_marker[0, 2])
    try:
        run = run_mock_skill("holistic_standoff", {"point": point, "grasp": "front", "yaw": yaw,
                                                   "size": [0.06, 0.06, 0.06]})
        assert run.status is SkillStatus.SUCCESS, run.failure
        out = run.outputs
        reached = Pose2D(*out["pose"])
        assert math.dist(out["pose"][:2], out["planned"][:2]) < 0.1
        # the arm is at the pre-grasp as seen from the pose the base reached
        T_pre = grasp_poses(grasp_frame(point, "front", yaw), 0, pre_grasp=(0.0, 0.0, 0.10)).pre_grasp
        q = mock_robot.arm.state().positions
        T = reached.matrix() @ np.asarray(mock_robot.arm.mount) @ wx250s().fk(q)
        assert np.linalg.norm(T[:3, 3] - T_pre[:3, 3]) < 0.01
        events = [e for e, _ in skill_ctx.events]
        assert "holistic_plan" in events and "base_status" in events
    finally:
        close_workspace(skill_ctx.world)


@pytest.mark.slow
def test_holistic_standoff_in_the_sim(tmp_path):
    """The skill on the simulated LoCoBot in the lab with a 0.45 m deep box on the floor in
    front of box_1 (no stand-off of the profile is free): the base stops where the plan
    said, away from the blocker, and the true arm holds the tool at the pre-grasp."""
    import io
    from pathlib import Path

    from mmexec.executive.config import LoadedConfig, build_robot
    from mmexec.executive.eventlog import read_log
    from mmexec.executive.runner import Progress, Runner, RunOptions
    from mmexec.skills.manipulation.holistic_skill import grasp_frame

    repo = Path(__file__).resolve().parents[3]
    world = (repo / "sim" / "worlds" / "lab.yaml").read_text()
    bin_line = "  - {name: bin, pose: [2.7, 1.3, 0.0], size: [0.3, 0.3, 0.6], shape: cylinder}\n"
    assert bin_line in world
    world = world.replace(bin_line, bin_line + "  - {name: blocker, pose: [4.33, 2.3, 0.0], size: [0.45, 0.4, 0.2], "
                                               "shape: box}\n")
    (tmp_path / "lab_blocked.yaml").write_text(world)
    config = (repo / "config" / "locobot_sim.yaml").read_text().replace("  world: lab\n", f"  world: {tmp_path / 'lab_blocked.yaml'}\n")
    (tmp_path / "sim.yaml").write_text(config)
    point, yaw = [4.575, 2.3, 0.28], math.pi  # box_1's centre; the gripper comes from the room (-x)
    (tmp_path / "mission.yaml").write_text(
        "mission: holistic_demo\ntree:\n  skill: holistic_standoff\n"
        f"  params: {{point: {point}, grasp: front, yaw: {yaw}, size: [0.06, 0.06, 0.06]}}\n")
    holder: dict = {}

    def factory(loaded: LoadedConfig):
        holder["robot"] = build_robot(loaded, seed=0)
        return holder["robot"]

    seen: dict = {}

    def on_record(record: dict) -> None:
        if record.get("event") == "request_end":  # SIM-ONLY ground truth, before the robot closes
            robot = holder["robot"]
            seen["base"] = robot.truth.base_pose()
            seen["q"] = list(robot.arm.state().positions)
            seen["mount"] = np.asarray(robot.arm.mount)

    opts = RunOptions(mission=tmp_path / "mission.yaml", config=tmp_path / "sim.yaml", requests=[], seed=0,
                      log_path=tmp_path / "events.jsonl")
    out = io.StringIO()
    runner = Runner(opts, out=out, err=out, progress=Progress(io.StringIO(), enabled=False), robot_factory=factory)
    runner.add_log_listener(on_record)
    runner.prepare()
    assert runner.run() == 0, out.getvalue()
    records = read_log(tmp_path / "events.jsonl")
    plan = next(r for r in records if r.get("event") == "holistic_plan")
    assert plan["success"] and plan["round"] == 0
    base = seen["base"]
    assert math.dist((base.x, base.y), plan["pose"][:2]) < 0.08  # navigation stopped near the planned pose
    # not on the blocker (x 4.105..4.555, y 2.1..2.5): behind or beside it, the footprint clear
    gap = math.hypot(max(4.105 - base.x, 0.0, base.x - 4.555), max(2.1 - base.y, 0.0, base.y - 2.5))
    assert gap > 0.17
    T_pre = grasp_poses(grasp_frame(point, "front", yaw), 0, pre_grasp=(0.0, 0.0, 0.10)).pre_grasp
    T = base.matrix() @ seen["mount"] @ wx250s().fk(seen["q"])
    assert np.linalg.norm(T[:3, 3] - T_pre[:3, 3]) < 0.02  # the true tool at the pre-grasp


def test_grasp_frames_and_world_targets(skill_ctx):
    """The skill's grasp frames (top: z up, fingers' travel at yaw; front: z at yaw, y up)
    and a grasp frame read from the world model, directly or inside a target."""
    from types import SimpleNamespace

    from mmexec.skills.base import SkillFailure
    from mmexec.skills.manipulation.holistic_skill import _frame_from_world, grasp_frame

    top = grasp_frame([1.0, 2.0, 0.5], "top", math.pi / 2)
    assert np.allclose(top[:3, 2], [0, 0, 1]) and np.allclose(top[:3, 0], [0, 1, 0]) and np.allclose(top[:3, 3], [1, 2, 0.5])
    front = grasp_frame([1.0, 2.0, 0.5], "front", math.pi)
    assert np.allclose(front[:3, 2], [-1, 0, 0]) and np.allclose(front[:3, 1], [0, 0, 1])
    for T in (top, front):
        assert np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3)) and np.linalg.det(T[:3, :3]) == pytest.approx(1.0)
    skill_ctx.world["t"] = SimpleNamespace(grasp=SimpleNamespace(T_map_top=top, T_map_front=front))
    assert np.allclose(_frame_from_world(skill_ctx, "t", "front"), front)
    skill_ctx.world["m"] = top.tolist()
    assert np.allclose(_frame_from_world(skill_ctx, "m", "top"), top)
    skill_ctx.world["bad"] = "shelf"
    with pytest.raises(SkillFailure, match="holds no 4x4 grasp frame"):
        _frame_from_world(skill_ctx, "bad", "top")
    with pytest.raises(SkillFailure, match="no world-model entry 'nope'"):
        _frame_from_world(skill_ctx, "nope", "top")
