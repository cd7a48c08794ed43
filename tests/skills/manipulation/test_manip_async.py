"""Planning off the tick thread: ArmPlanner.stop ends a running plan early, IK seeds pick
the solution family, and the fetch skills' off_tick helper yields, returns, and on
cancellation stops the planner and waits for it before re-raising."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from mmexec.drivers.interfaces import SceneBox
from mmexec.skills.base import SkillCancelled, SkillContext
from mmexec.skills.manipulation import (
    CANCELLED,
    ArmModel,
    ArmPlanner,
    PlannerConfig,
    PlanningScene,
    grasp_poses,
    wx250s,
)
from mmexec.skills.manipulation.arm import ArmSettings, ArmWorkspace, off_tick


@pytest.fixture(scope="module")
def kin():
    return wx250s(locobot=True)


@pytest.fixture
def scene():
    sc = PlanningScene(ArmModel.from_sim_model("locobot_wx250s"))
    yield sc
    sc.close()


def _walled_off(scene: PlanningScene) -> tuple[list[float], list[float]]:
    """Two valid postures on either side of a wall in the arm's y = 0 plane (in front of
    the waist axis and between it and the camera tower), so no plan exists and OMPL runs
    to its time limit."""
    boxes = []
    for name, x0, x1, z0, z1 in (("front", 0.056, 1.0, 0.02, 2.0), ("rear", -0.099, -0.056, 0.02, 0.40)):
        T = np.eye(4)
        T[:3, 3] = ((x0 + x1) / 2, 0.0, (z0 + z1) / 2)
        boxes.append(SceneBox(name, T, (x1 - x0, 0.01, z1 - z0)))
    scene.set_static_boxes(boxes)
    return [-1.2, 0.3, 0.0, 0.0, 0.0, 0.0], [1.2, 0.3, 0.0, 0.0, 0.0, 0.0]


def test_stop_ends_a_running_plan_early(scene, kin):
    q0, q1 = _walled_off(scene)
    assert scene.is_valid(q0) and scene.is_valid(q1)
    planner = ArmPlanner(scene, kin, PlannerConfig(time_limit=0.3, attempts=1))
    assert planner.plan(q0, q1).reason.startswith("no plan within")  # really disconnected
    planner = ArmPlanner(scene, kin, PlannerConfig(time_limit=5.0, attempts=3))
    timer = threading.Timer(0.3, planner.stop.set)
    t0 = time.perf_counter()
    timer.start()
    res = planner.plan(q0, q1)
    took = time.perf_counter() - t0
    timer.cancel()
    assert not res.success and res.reason == CANCELLED
    assert took < 1.5, f"planner ran {took:.2f} s after stop"


def test_stop_set_before_the_call_cancels_every_kind_of_query(scene, kin):
    planner = ArmPlanner(scene, kin)
    planner.stop.set()
    q0 = [0.0, -0.4, 1.1, 0.0, 1.4, 0.0]
    T = kin.fk([0.0, 0.2, 0.3, 0.0, -0.5, 0.0])
    assert planner.plan_to_pose(q0, T, ik_seeds=[[0.0] * 6]).reason == CANCELLED
    assert planner.cartesian_path(q0, T).reason == CANCELLED
    planner.stop.clear()
    assert planner.cartesian_path(q0, kin.fk(q0) @ np.diag([1, 1, 1, 1.0])).success


def test_ik_seed_keeps_the_natural_solution_family(scene, kin):
    # marker on a shelf 0.45 m ahead, 0.42 m above the arm base, facing the robot
    T_m = np.eye(4)
    T_m[:3, :3] = np.column_stack([[0, -1, 0], [0, 0, 1], [-1, 0, 0]])
    T_m[:3, 3] = (0.45, 0.0, 0.42)
    poses = grasp_poses(T_m, kin.approach_axis, grasp_depth=0.03)
    planner = ArmPlanner(scene, kin)
    res = planner.plan_to_pose([0.0, -0.4, 1.1, 0.0, 1.4, 0.0], poses.pre_grasp, ik_seeds=[[0.0] * 6])
    assert res.success, res.reason
    q = res.path[-1]
    assert abs(q[0]) < 0.2 and abs(q[3]) < 0.2  # waist towards the target, forearm not rolled over
    assert np.allclose(kin.fk(q)[:3, 3], poses.pre_grasp[:3, 3], atol=1e-3)


def _ws(scene: PlanningScene, kin) -> ArmWorkspace:
    return ArmWorkspace(ArmSettings(plan_slice=0.0), kin, scene, ArmPlanner(scene, kin))


def test_off_tick_yields_until_the_job_is_done_and_returns_its_result(scene, kin):
    ws = _ws(scene, kin)
    release = threading.Event()
    ran_on: list[str] = []

    def job() -> int:
        ran_on.append(threading.current_thread().name)
        release.wait(5.0)
        return 42

    gen = off_tick(SkillContext(robot=None, clock=None), ws, job)  # type: ignore[arg-type]
    for _ in range(3):
        assert next(gen) is None  # the tick goes on while the job runs
    release.set()
    with pytest.raises(StopIteration) as done:
        while True:
            next(gen)
    assert done.value.value == 42
    assert ran_on and ran_on[0].startswith("arm-planner") and ran_on[0] != threading.current_thread().name
    ws.executor.shutdown(wait=True)


def test_off_tick_cancel_stops_the_planner_and_waits_for_it(scene, kin):
    q0, q1 = _walled_off(scene)
    ws = _ws(scene, kin)
    cfg = PlannerConfig(time_limit=5.0, attempts=2)
    results = []

    def job():
        r = ws.planner.plan(q0, q1, cfg)
        results.append(r)
        return r

    gen = off_tick(SkillContext(robot=None, clock=None), ws, job)  # type: ignore[arg-type]
    next(gen)
    t0 = time.perf_counter()
    with pytest.raises(SkillCancelled):
        gen.throw(SkillCancelled())
        while True:
            gen.send(None)
    took = time.perf_counter() - t0
    assert results and results[0].reason == CANCELLED  # the job had returned before the re-raise
    assert took < 2.0
    assert not ws.planner.stop.is_set()  # cleared for the next plan
    ws.executor.shutdown(wait=True)
