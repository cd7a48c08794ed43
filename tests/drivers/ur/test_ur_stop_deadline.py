"""The stop deadline comes from the model's joint speed limits and the stop deceleration
(issue 9): a UR3e wrist at 2 pi rad/s braking at 2 rad/s^2 needs 3.14 s, more than the
3 s one constant allowed, so a stop at full wrist speed was reported as failed.

Motion runs on the fake controller's stepped clock; the assertions are about clock time
and goal states, never wall time.
"""

from __future__ import annotations

import math
import threading

import pytest
from urtest_helpers import run_for, step_until, sync, wait_for

from mmexec.drivers.interfaces import GoalState, JointTrajectory, ManualClock
from mmexec.drivers.ur.arm import URArm, URArmConfig
from mmexec.drivers.ur.fake import FakeURController

HOME = (0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0)


@pytest.mark.parametrize(("model", "top_speed"), [("ur5e", math.pi), ("ur3e", 2.0 * math.pi)])
def test_stop_at_full_wrist_speed_ends_cancelled(model: str, top_speed: float) -> None:
    baseline = threading.active_count()
    clock = ManualClock()
    ctrl = FakeURController(clock, model=model)
    arm = URArm(URArmConfig(host=f"fake-{model}", model=model, frequency=200.0), clock=clock,
                control_factory=ctrl.control_factory, receive_factory=ctrl.receive_factory)
    try:
        arm.open()
        # wrist 3 at its speed limit for 2 s (UR5e: 0 -> 2 pi; the UR3e's wrist 3 is continuous)
        goal = arm.follow(JointTrajectory(arm.joint_names, (2.0,), (HOME[:5] + (2.0 * top_speed,),)))
        run_for(arm, clock, 0.6)
        assert arm.state().velocities[5] == pytest.approx(top_speed, rel=1e-3)
        goal.cancel()
        sync(arm, clock)  # the worker sent the stop at this clock time, from full speed
        took = step_until(arm, clock, goal)
        assert goal.state is GoalState.CANCELLED, goal.reason
        braking = top_speed / arm.config.stop_deceleration  # UR5e 1.57 s, UR3e 3.14 s (> the old 3 s)
        assert took == pytest.approx(braking, abs=0.03)  # at rest on the 0.02 s grid of the stepped clock
        assert arm.config.stop_deadline() == pytest.approx(1.25 * braking + arm.config.command_timeout)
    finally:
        arm.close()
    assert wait_for(lambda: threading.active_count() == baseline)


def test_derived_deadlines_and_an_explicit_stop_timeout() -> None:
    assert URArmConfig(host="h", model="ur5e").stop_deadline() == pytest.approx(1.25 * math.pi / 2 + 0.5)
    assert URArmConfig(host="h", model="ur3e").stop_deadline() == pytest.approx(1.25 * math.pi + 0.5)
    # a harder stop brakes sooner, and the deadline follows
    assert URArmConfig(host="h", model="ur3e", stop_deceleration=4.0).stop_deadline() == pytest.approx(
        1.25 * math.pi / 2 + 0.5)
    assert URArmConfig(host="h", model="ur5e", stop_timeout=2.0).stop_deadline() == 2.0
    with pytest.raises(ValueError) as e:
        URArmConfig(host="h", model="ur3e", stop_timeout=3.0)
    assert str(e.value) == (
        "URArmConfig.stop_timeout 3 s is shorter than braking the ur3e's fastest joint from its speed limit "
        "(6.283 rad/s at stop_deceleration 2 rad/s^2: 3.14 s); raise it, or leave it unset to derive it (4.43 s)")
    for bad in (0.0, math.inf, math.nan):
        with pytest.raises(ValueError, match="stop_timeout must be > 0 and finite"):
            URArmConfig(host="h", stop_timeout=bad)
    with pytest.raises(ValueError, match="stop_deceleration must be > 0 and finite, got inf"):
        URArmConfig(host="h", stop_deceleration=math.inf)
