"""A lost link stops the arm: the driver arms ur_rtde's controller-side RTDE watchdog at
bring-up and kicks it every cycle (issue 9).

The controller is :class:`FakeURController` on a stepped clock (controller time), which
models ur_rtde's control script: a lost link alone does not stop the arm (a moveJ runs
to its end, a servo target is held), an armed watchdog stops the program when no command
package arrives for 1 / f s. What is asserted is the controller's record of that stop
(clock time, position), never a wall-clock duration. Before the fix the driver never
called setWatchdog: no stop was recorded and the moveJ ran on to its target.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Iterator

import pytest
from urtest_helpers import run_for, start_stub, step_until, sync, wait_for

from mmexec.drivers.interfaces import Goal, GoalState, JointTrajectory, ManualClock
from mmexec.drivers.ur.arm import URArm, URArmConfig, URConnectionError
from mmexec.drivers.ur.fake import FakeURController
from mmexec.drivers.ur.rtde_host import RTDEHost

HOME = (0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0)
TARGET = 1.5  # rad on the shoulder pan joint


def _q(j0: float) -> tuple[float, ...]:
    return (j0,) + HOME[1:]


Rig = tuple[URArm, FakeURController, ManualClock]


def _rig(**cfg: float) -> Rig:
    clock = ManualClock()
    ctrl = FakeURController(clock)
    config = URArmConfig(host="fake-ur", frequency=200.0, command_timeout=0.3, connect_timeout=2.0,
                         **cfg)  # type: ignore[arg-type]
    arm = URArm(config, clock=clock, control_factory=ctrl.control_factory, receive_factory=ctrl.receive_factory)
    return arm, ctrl, clock


@pytest.fixture
def rig() -> Iterator[Rig]:
    baseline = threading.active_count()
    arm, ctrl, clock = _rig()
    arm.open()
    yield arm, ctrl, clock
    ctrl.release_blocked_calls()
    arm.close()
    assert wait_for(lambda: threading.active_count() == baseline), "worker thread leaked"


def _start(arm: URArm, clock: ManualClock, motion: str) -> Goal:
    """A motion towards TARGET, running at speed after 0.4 s of clock time."""
    if motion == "follow":
        goal = arm.follow(JointTrajectory(arm.joint_names, (2.0,), (_q(TARGET),)))
    else:
        goal = arm.move_to(_q(TARGET), speed_scale=1.0)
    run_for(arm, clock, 0.4)
    assert goal.state is GoalState.ACTIVE and arm.state().velocities[0] > 0.5
    return goal


def _stall(ctrl: FakeURController) -> None:
    ctrl.command_delay = 60.0  # every control call hangs (a host or link that stopped answering)


#: how the link is cut: the socket closes; the controller stops receiving (state still
#: arrives, so the driver sees nothing wrong); the driver's calls hang
CUTS: dict[str, Callable[[FakeURController], None]] = {
    "closed": FakeURController.drop_connections,
    "not received": FakeURController.drop_commands,
    "calls hang": _stall,
}


@pytest.mark.parametrize("motion", ["move_to", "follow"])
@pytest.mark.parametrize("cut", list(CUTS))
def test_lost_link_stops_the_arm_within_the_watchdog_period(rig: Rig, motion: str, cut: str) -> None:
    arm, ctrl, clock = rig
    goal = _start(arm, clock, motion)
    t_cut = clock.now()
    CUTS[cut](ctrl)
    if cut == "calls hang":  # the worker is stuck in a call: the clock runs on without it
        for _ in range(25):
            clock.advance(0.02)
        assert wait_for(goal.done, 10.0)  # the call deadline (command_timeout) fails the goal
    else:
        step_until(arm, clock, goal, limit=1.0)
    assert goal.state is GoalState.FAILED
    expected = {"closed": ("connection lost: RTDE link to fake-ur closed",),
                "not received": ("program stopped (runtime state 1: stopped)",),
                # the call deadline, or a read that saw the program stopped before a call hung
                "calls hang": ("connection lost: ur_rtde ", "program stopped (runtime state 1: stopped)")}[cut]
    assert goal.reason.startswith(expected), goal.reason
    period = 1.0 / arm.config.watchdog_frequency
    clock.advance(period)  # the controller's time goes on (the driver detected the loss first)
    (stop,) = ctrl.watchdog_stops
    assert stop.period == pytest.approx(period)
    assert t_cut - 1e-9 <= stop.t <= t_cut + period + 1e-9  # within the watchdog period of the cut
    if motion == "move_to":  # the moveJ alone would have run on to the target
        assert stop.qd[0] > 0.5
    probe = ctrl.receive_factory("probe")
    q_stop = probe.getActualQ()
    clock.advance(2.0)
    assert probe.getActualQ() == q_stop and probe.getActualQd() == [0.0] * 6
    assert probe.getRuntimeState() == 1
    assert q_stop[0] < TARGET - 0.3  # stopped on the way


def test_without_the_watchdog_the_move_runs_on() -> None:
    """What the watchdog prevents, shown on the fake: a moveJ on a lost link (no
    setWatchdog) runs on to its target."""
    clock = ManualClock()
    ctrl = FakeURController(clock)
    ctl, rcv = ctrl.control_factory("h"), ctrl.receive_factory("h")
    assert ctl.moveJ(list(_q(TARGET)), math.pi, 1.4, True)
    clock.advance(0.4)
    ctrl.drop_connections()
    clock.advance(5.0)
    probe = ctrl.receive_factory("probe")
    assert probe.getActualQ()[0] == pytest.approx(TARGET) and probe.getRuntimeState() == 2
    assert ctrl.watchdog_stops == [] and not rcv.isConnected()


def test_healthy_link_keeps_the_program_running(rig: Rig) -> None:
    arm, ctrl, clock = rig
    goal = arm.move_to(_q(0.5), speed_scale=1.0)
    step_until(arm, clock, goal, dt=0.05)
    assert goal.state is GoalState.SUCCEEDED
    run_for(arm, clock, 2.0, dt=0.05)  # idle: the cycle's kick keeps the program alive
    assert ctrl.watchdog_stops == [] and arm.status().fault == ""


def test_watchdog_frequency_from_the_config() -> None:
    arm, ctrl, clock = _rig(watchdog_frequency=4.0)
    try:
        arm.open()
        goal = _start(arm, clock, "move_to")
        t_cut = clock.now()
        ctrl.drop_commands()
        step_until(arm, clock, goal, limit=1.0)
        (stop,) = ctrl.watchdog_stops
        assert stop.period == pytest.approx(0.25) and t_cut + 0.25 - 0.02 - 1e-9 <= stop.t <= t_cut + 0.25 + 1e-9
        assert goal.reason.startswith("program stopped")
    finally:
        arm.close()


def test_reconnect_after_a_watchdog_stop_starts_the_program_again(rig: Rig) -> None:
    arm, ctrl, clock = rig
    goal = _start(arm, clock, "move_to")
    ctrl.drop_connections()
    step_until(arm, clock, goal, limit=1.0)
    clock.advance(1.0)
    assert len(ctrl.watchdog_stops) == 1
    r = arm.reconnect()
    assert wait_for(r.done) and r.state is GoalState.SUCCEEDED
    sync(arm, clock)
    assert arm.status().runtime_state == 2 and arm.status().fault == ""
    g = arm.move_to(_q(0.2), speed_scale=1.0)
    step_until(arm, clock, g)
    assert g.state is GoalState.SUCCEEDED
    # armed again on the new connection
    g = _start(arm, clock, "move_to")
    ctrl.drop_connections()
    step_until(arm, clock, g, limit=1.0)
    clock.advance(0.1)
    assert len(ctrl.watchdog_stops) == 2


def test_a_controller_that_refuses_the_watchdog_fails_bring_up_in_one_line() -> None:
    arm, ctrl, _clock = _rig()
    ctrl.protective_stop()
    with pytest.raises(URConnectionError) as e:
        arm.open()
    arm.close()
    assert str(e.value) == "UR fake-ur:30004: cannot connect: controller refused setWatchdog(10 Hz): protective stop"
    assert ctrl.connections == ctrl.disconnects == 2


@pytest.mark.parametrize(
    ("cfg", "problem"),
    [
        ({"watchdog_frequency": math.nan}, "watchdog_frequency must be > 0 and finite, got nan"),
        ({"watchdog_frequency": math.inf}, "watchdog_frequency must be > 0 and finite, got inf"),
        ({"watchdog_frequency": 0.0}, "watchdog_frequency must be > 0 and finite, got 0.0"),
        ({"watchdog_frequency": 0.5}, "watchdog_frequency must be within [1, 50] Hz, got 0.5"),
        ({"watchdog_frequency": 100.0}, "watchdog_frequency must be within [1, 50] Hz, got 100"),
        ({"watchdog_frequency": 40.0, "frequency": 50.0},
         ("watchdog_frequency 40 Hz needs frequency >= 80 Hz (the watchdog is kicked once per cycle, at least "
          "twice per watchdog period), got 50 Hz")),
    ],
)
def test_watchdog_frequency_is_validated(cfg: dict[str, float], problem: str) -> None:
    with pytest.raises(ValueError) as e:
        URArmConfig(host="h", **cfg)  # type: ignore[arg-type]
    assert str(e.value) == f"URArmConfig.{problem}"


# --------------------------------------------------------------------------- over real sockets
# The RTDE stub models the same controller behaviour on the wire: a watchdog on an RTDE
# input variable. ur_rtde's control interface (which feeds input_int_register_0) cannot
# run against the stub (docs/protocols.md 4.5), so the real ur_rtde IO interface, in the
# driver's host process, feeds input_int_register_18 the same way, one data package per
# call. The link is then cut three ways; the stub records when it stopped the program.

LIMIT = 30.0  # [wall s] generous bound on a wait that only matters when something is broken


@pytest.mark.parametrize("cut", ["host killed", "closed", "not received"])
def test_stub_controller_stops_the_moving_arm_when_its_input_goes_silent(cut: str) -> None:
    stub = start_stub()
    host = RTDEHost(stub.host)
    done = threading.Event()
    errors: list[BaseException] = []
    kicker: threading.Thread | None = None
    try:
        host.start(LIMIT)
        io = host.construct("rtde_io", "RTDEIOInterface", (stub.host,), timeout=LIMIT, call_timeout=LIMIT)

        def kick() -> None:
            n = 0
            while not done.is_set():
                try:
                    io.setInputIntRegister(18, n)
                except RuntimeError as e:  # the link is gone (the host killed, the pipe broken)
                    errors.append(e)
                    return
                n += 1
                done.wait(0.01)

        kicker = threading.Thread(target=kick, daemon=True)
        kicker.start()
        assert wait_for(lambda: len(stub.stats()["inputs"]) >= 5, LIMIT)  # the packages flow: arm it
        # 2 Hz: a period a loaded test machine's kicker thread keeps to (the controller's
        # behaviour does not depend on it)
        stub.watchdog(2.0, "input_int_register_18")
        stub.move([0.5, 0.0, 0.0, 0.0, 0.0, 0.0])
        assert wait_for(lambda: stub.stats()["watchdog_updates"] >= 20, LIMIT)
        before = stub.stats()
        assert before["watchdog_stops"] == [] and before["runtime_state"] == 2  # fed: the program runs
        assert wait_for(lambda: stub.stats()["q"][0] > before["q"][0], LIMIT)  # and the arm moves
        if cut == "host killed":
            host.kill("the test cut the link")
        elif cut == "closed":
            stub.drop_connections()
        else:
            stub.deaf(True)
        assert wait_for(lambda: stub.stats()["watchdog_stops"] != [], LIMIT)
        after = stub.stats()
        (stop,) = after["watchdog_stops"]
        assert stop["variable"] == "input_int_register_18" and stop["period"] == pytest.approx(0.5)
        assert stop["t"] == pytest.approx(stop["last_update"] + 0.5)  # one period after the last update
        assert stop["qd"][0] == pytest.approx(0.5)  # moving until then
        assert after["runtime_state"] == 1 and after["qd"] == [0.0] * 6
        assert after["q"] == pytest.approx(stop["q"]) and stub.stats()["q"] == pytest.approx(stop["q"])
    finally:
        done.set()
        host.kill("test over")  # never disconnect() a deaf peer: it waits for an answer for good
        if kicker is not None:
            kicker.join(LIMIT)
        host.close()
        stub.stop()
    assert all(isinstance(e, RuntimeError) for e in errors)


class _Recorder:
    """The control interface, recording the name of every method called on it."""

    def __init__(self, inner: object, calls: list[str]) -> None:
        self._inner, self._calls = inner, calls

    def __getattr__(self, name: str) -> object:
        attr = getattr(self._inner, name)
        if not callable(attr):
            return attr

        def recorded(*args: object) -> object:
            self._calls.append(name)
            return attr(*args)

        return recorded


def test_one_command_package_per_cycle_feeds_the_watchdog() -> None:
    """A cycle that sends a command (a servoJ while following) sends no kick: a second
    package in the same controller cycle could overwrite the first's registers; a cycle
    that sends none (a moveJ running) kicks once."""
    clock = ManualClock()
    ctrl = FakeURController(clock)
    calls: list[str] = []
    arm = URArm(URArmConfig(host="fake-ur", frequency=200.0), clock=clock,
                control_factory=lambda h, f: _Recorder(ctrl.control_factory(h, f), calls),
                receive_factory=ctrl.receive_factory)
    try:
        arm.open()
        for start in (lambda: arm.follow(JointTrajectory(arm.joint_names, (0.5,), (_q(0.3),))),
                      lambda: arm.move_to(_q(0.0), speed_scale=1.0)):
            goal = start()
            step_until(arm, clock, goal)
            assert goal.state is GoalState.SUCCEEDED
    finally:
        arm.close()
    streaming = calls[calls.index("servoJ"):len(calls) - calls[::-1].index("servoJ")]
    assert streaming.count("servoJ") > 10 and "kickWatchdog" not in streaming  # servoJ feeds it
    moving = calls[calls.index("moveJ"):]
    assert moving.count("kickWatchdog") > 10  # a running moveJ sends nothing: the cycle kicks
