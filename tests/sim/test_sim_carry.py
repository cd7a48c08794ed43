"""A held item rides along with the kinematically moved base (driving, turning, backing
off), at the physics rate the fetch configs use; it is still dropped when grasped badly."""

from __future__ import annotations

import numpy as np
import pytest

from mmexec.drivers.interfaces import GoalState, GraspState, Pose2D
from mmexec.sim.backend import build


def _run(r, goal, limit=10.0):
    t0 = r.clock.now()
    while not goal.done() and r.clock.now() - t0 < limit:
        r.spin(0.05)
    return goal


def _rel(r, name):
    T_tool = r.core.link_T(r.core.info.tool_link)
    return np.linalg.inv(T_tool) @ r.truth.item_pose(name)


@pytest.fixture
def holding(sim_section, bench_world):
    r = build(sim_section(f"world: {bench_world}\nphysics_hz: 60\n"), profile={}, seed=1, options={})
    try:
        r.base.stop()
        r.spin(0.5)
        r.gripper.set_width(0.074)
        r.arm.set_positions([0.0] * 6)
        r.core.place_base(Pose2D(1.0, 2.2, 0.0))
        r.spin(0.05)
        assert _run(r, r.gripper.close(force=5.0)).result.grasp is GraspState.CONTACT_CLOSING
        assert _run(r, r.arm.move_to([0.0, -0.3, 0.0, 0.0, 0.3, 0.0])).state is GoalState.SUCCEEDED
        yield r
    finally:
        r.close()


@pytest.mark.parametrize("v,w", [(-0.6, 0.0), (0.3, 0.0), (0.0, 2.0), (-0.2, 1.0)])
def test_held_item_moves_with_the_base(holding, v, w):
    r = holding
    rel0 = _rel(r, "cube")
    start = r.truth.base_pose()
    for _ in range(20):  # 1 s at the commanded speed (after the 1 m/s^2 ramp)
        r.base.set_velocity(v, w)
        r.spin(0.05)
    for _ in range(10):
        r.base.stop()
        r.spin(0.05)
    moved = r.truth.base_pose()
    assert abs(moved.x - start.x) + abs(moved.theta - start.theta) > 0.1  # the base really went somewhere
    assert r.truth.held_item() == "cube"
    assert r.gripper.state().grasp is GraspState.CONTACT_CLOSING
    drift = np.linalg.norm(_rel(r, "cube")[:3, 3] - rel0[:3, 3])
    assert drift < 0.005, f"item moved {drift * 1e3:.1f} mm in the gripper"


def test_grasp_slip_fault_still_drops_while_driving(sim_section, bench_world):
    r = build(sim_section(f"world: {bench_world}\nphysics_hz: 60\nfaults:\n  grasp_slip: {{after: 0.5, items: [cube]}}\n"),
              profile={}, seed=1, options={})
    try:
        r.gripper.set_width(0.074)
        r.arm.set_positions([0.0] * 6)
        r.core.place_base(Pose2D(1.0, 2.2, 0.0))
        r.spin(0.05)
        assert _run(r, r.gripper.close(force=5.0)).result.grasp is GraspState.CONTACT_CLOSING
        for _ in range(30):
            r.base.set_velocity(-0.3, 0.0)
            r.spin(0.05)
        assert r.truth.held_item() is None
        assert r.gripper.state().grasp is GraspState.DROPPED
    finally:
        r.close()
