"""KobukiDevice and KobukiBase against the protocol fake on a pty."""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import pytest

from mmexec.drivers.fakes.kobuki import KobukiFake
from mmexec.drivers.interfaces import CapabilityError, ManualClock, Pose2D
from mmexec.drivers.kobuki import codec as k
from mmexec.drivers.kobuki.base import KobukiBase
from mmexec.drivers.kobuki.device import (
    KobukiConfig,
    KobukiCorruptFrames,
    KobukiDevice,
    KobukiFirmwareError,
    KobukiPortError,
    KobukiTimeout,
    LinkState,
)
from mmexec.drivers.transport import SerialSettings, SerialTransport

Waiter = Callable[..., bool]
FAST = {"linear_accel": 5.0, "angular_accel": 20.0}


def _device(fake: KobukiFake, clock: ManualClock | None = None, **kw: object) -> KobukiDevice:
    return KobukiDevice(KobukiConfig(port=fake.port, **kw), clock)  # type: ignore[arg-type]


def test_connect_reads_versions_and_close_leaves_no_thread(fake: KobukiFake, wait_until: Waiter) -> None:
    dev = _device(fake)
    info = dev.connect()
    try:
        assert info.firmware == k.Version(1, 2, 0) and info.hardware == k.Version(1, 0, 4)
        assert info.unique_id == fake.state.unique_id and info.battery == pytest.approx(16.5)
        assert dev.link_state is LinkState.STREAMING
        # versions answered: the driver stops requesting them
        n = len(fake.snapshot().requests)
        time.sleep(0.1)
        assert len(fake.snapshot().requests) == n
        # one Base Control frame per feedback frame
        assert wait_until(lambda: fake.snapshot().base_control_frames >= 5)
    finally:
        dev.close()
    assert dev.link_state is LinkState.CLOSED


def test_drive_odometry_and_acceleration_limit(fake: KobukiFake, wait_until: Waiter) -> None:
    clock = ManualClock()
    dev = _device(fake, clock)
    base = KobukiBase(dev)
    dev.connect()
    try:
        base.set_velocity(0.2, 0.0)
        assert wait_until(lambda: fake.snapshot().speed > 0)
        # the first frames ramp at 0.3 m/s^2: ~6 mm/s per 20 ms frame
        assert fake.snapshot().speed <= 8
        assert wait_until(lambda: fake.snapshot().speed == 200, 1.5)
        assert wait_until(lambda: base.state().pose.x > 0.03)
        st = base.state()
        truth = fake.snapshot()
        assert st.pose.x == pytest.approx(truth.x, abs=0.006)
        assert abs(st.pose.y) < 1e-3 and st.v == pytest.approx(0.2, abs=0.01)
        assert not st.faults
    finally:
        base.close()
    assert wait_until(lambda: fake.snapshot().speed == 0 and fake.snapshot().radius == 0, 0.5)  # close sent zero


def test_limits_enforced_whatever_is_asked(fake: KobukiFake, wait_until: Waiter) -> None:
    dev = _device(fake, ManualClock(), **FAST)
    dev.connect()
    try:
        dev.set_velocity(5.0, 0.0)
        assert wait_until(lambda: dev.output == (0.7, 0.0))
        assert wait_until(lambda: fake.snapshot().speed == 700)
        dev.set_velocity(0.0, -10.0)
        assert wait_until(lambda: dev.output == (0.0, -math.pi))
        assert wait_until(lambda: fake.snapshot().speed == round(-1000 * 0.23 * math.pi / 2))
        assert fake.snapshot().radius == 1
    finally:
        dev.close()


def test_decelerates_faster_than_it_accelerates(fake: KobukiFake, wait_until: Waiter) -> None:
    dev = _device(fake, ManualClock(), linear_accel=1.0)
    dev.connect()
    try:
        dev.set_velocity(0.3, 0.0)
        assert wait_until(lambda: dev.output[0] == 0.3)
        dev.set_velocity(0.0, 0.0)
        assert wait_until(lambda: 0.0 < dev.output[0] < 0.3, 0.5)
        first = dev.output[0]
        # one frame at 20 ms decelerates by 1.2 * 1.0 * 0.02 = 0.024 m/s
        assert 0.3 - first == pytest.approx(0.024, abs=0.025)
        assert wait_until(lambda: dev.output == (0.0, 0.0))
    finally:
        dev.close()


@pytest.mark.parametrize(
    ("field", "bits", "name"),
    [("bumper", 0x04, "bumper_left"), ("cliff", 0x02, "cliff_centre"), ("wheel_drop", 0x01, "wheel_drop_right"),
     ("overcurrent", 0x01, "overcurrent_left")],
)
def test_safety_sensor_stops_at_once_and_refuses_motion(fake: KobukiFake, field: str, bits: int, name: str, wait_until: Waiter) -> None:
    dev = _device(fake, ManualClock(), **FAST)
    base = KobukiBase(dev)
    dev.connect()
    try:
        base.set_velocity(0.3, 0.0)
        assert wait_until(lambda: fake.snapshot().speed == 300)
        fake.set_sensors(**{field: bits})
        # stop within a couple of frames, without ramping
        assert wait_until(lambda: fake.snapshot().speed == 0, 0.2)
        assert name in base.state().faults
        assert dev.set_velocity(0.2, 0.0) is False
        base.set_velocity(0.2, 0.0)
        time.sleep(0.08)
        assert fake.snapshot().speed == 0
        fake.set_sensors(**{field: 0})
        assert wait_until(lambda: not base.state().faults)
        # the stop is latched: nothing moves until a new command arrives
        time.sleep(0.06)
        assert fake.snapshot().speed == 0
        assert dev.set_velocity(0.2, 0.0) is True
        assert wait_until(lambda: fake.snapshot().speed == 200)
    finally:
        dev.close()


def test_command_watchdog_zeroes_stale_velocity(fake: KobukiFake, wait_until: Waiter) -> None:
    clock = ManualClock()
    dev = _device(fake, clock, **FAST)
    dev.connect()
    try:
        dev.set_velocity(0.2, 0.5)
        assert wait_until(lambda: dev.output == (0.2, 0.5))
        clock.advance(0.5)
        time.sleep(0.06)
        assert dev.output == (0.2, 0.5)  # still within 0.6 s
        clock.advance(0.2)
        assert wait_until(lambda: fake.snapshot().speed == 0 and dev.output == (0.0, 0.0), 0.5)
    finally:
        dev.close()


def test_silence_is_link_lost_and_recovers(fake: KobukiFake, wait_until: Waiter) -> None:
    dev = _device(fake, ManualClock(), **FAST)
    dev.connect()
    try:
        dev.set_velocity(0.2, 0.0)
        fake.silent = True
        assert wait_until(lambda: "link_lost" in dev.faults, 0.5)
        assert dev.output == (0.0, 0.0)
        assert dev.set_velocity(0.2, 0.0) is False
        fake.silent = False
        assert wait_until(lambda: not dev.faults, 0.5)
    finally:
        dev.close()


def test_unplug_mid_motion_latches_link_lost(fake: KobukiFake, wait_until: Waiter) -> None:
    dev = _device(fake, ManualClock(), **FAST)
    dev.connect()
    try:
        dev.set_velocity(0.3, 0.0)
        assert wait_until(lambda: fake.snapshot().speed == 300)
        fake.unplug()
        assert wait_until(lambda: "link_lost" in dev.faults, 0.5)
        assert dev.output == (0.0, 0.0)
    finally:
        dev.close()
    assert dev.link_state is LinkState.CLOSED


def test_reconnect_after_close(fake: KobukiFake) -> None:
    dev = _device(fake)
    dev.connect()
    dev.close()
    info = dev.reconnect()
    try:
        assert info.firmware == k.Version(1, 2, 0)
    finally:
        dev.close()


def test_firmware_major_2_refused(fake: KobukiFake) -> None:
    fake.set_firmware(2, 0, 0)
    dev = _device(fake)
    with pytest.raises(KobukiFirmwareError, match=r"firmware 2\.0\.0 is not supported"):
        dev.connect()
    assert dev.link_state is LinkState.CLOSED


def test_corrupt_stream_refused_at_connect(fake: KobukiFake) -> None:
    fake.corrupt_next(1000)
    with pytest.raises(KobukiCorruptFrames, match="corrupt frames"):
        _device(fake, connect_timeout=0.2).connect()


def test_silent_device_times_out(fake: KobukiFake) -> None:
    fake.silent = True
    with pytest.raises(KobukiTimeout, match=r"no answer within 0\.2 s"):
        _device(fake, connect_timeout=0.2).connect()


def test_no_such_port(no_leaked_threads: None) -> None:
    with pytest.raises(KobukiPortError, match="kobuki on /dev/nope-kobuki: no such port"):
        KobukiDevice(KobukiConfig(port="/dev/nope-kobuki")).connect()


def test_stream_faults_do_not_disturb_the_driver(fake: KobukiFake, wait_until: Waiter) -> None:
    dev = _device(fake, ManualClock())
    dev.connect()
    try:
        before = dev.info().frames
        fake.stray_bytes()
        fake.truncate_next(1)
        fake.corrupt_next(2)
        fake.unknown_subpayload_next(3)
        assert wait_until(lambda: dev.info().frames >= before + 8)
        assert dev.info().bad_frames >= 3
        assert not dev.faults
        fb = dev.feedback
        assert fb is not None and fb.core is not None
    finally:
        dev.close()


def test_encoder_and_timestamp_wrap_keep_odometry_smooth(fake: KobukiFake, wait_until: Waiter) -> None:
    dev = _device(fake, ManualClock(), gyro_heading=False, **FAST)
    dev.connect()
    try:
        fake.set_counters(encoders=65400, timestamp_ms=65400)
        dev.set_velocity(0.3, 0.0)
        assert wait_until(lambda: fake.snapshot().timestamp_ms < 1000 and fake.snapshot().left_encoder > 66000)
        x0, truth0 = dev.base_state().pose.x, fake.snapshot().x
        time.sleep(0.2)
        x1, truth1 = dev.base_state().pose.x, fake.snapshot().x
        assert x1 - x0 == pytest.approx(truth1 - truth0, abs=0.01)
        assert 0.0 <= dev.base_state().v <= 0.31
    finally:
        dev.close()


def test_rotation_with_gyro_heading_and_reset_pose(fake: KobukiFake, wait_until: Waiter) -> None:
    dev = _device(fake, ManualClock(), **FAST)
    base = KobukiBase(dev)
    dev.connect()
    try:
        base.reset_pose(Pose2D(1.0, 2.0, 0.5))
        base.set_velocity(0.0, 1.0)
        assert wait_until(lambda: base.state().pose.theta > 0.8)
        base.stop()
        assert wait_until(lambda: fake.snapshot().speed == 0)
        time.sleep(0.05)
        st, truth = base.state(), fake.snapshot()
        assert st.pose.theta - 0.5 == pytest.approx(truth.heading, abs=0.01)
        assert st.pose.x == pytest.approx(1.0, abs=1e-3) and st.pose.y == pytest.approx(2.0, abs=1e-3)
    finally:
        base.close()


def test_sounds_leds_and_gains_reach_the_robot(fake: KobukiFake, wait_until: Waiter) -> None:
    dev = _device(fake)
    dev.connect()
    try:
        dev.play_sound_sequence(4)
        dev.play_tone(440.0, 0.1)
        dev.set_leds(led1="orange")
        dev.set_leds(led2="green")
        dev.set_gains(90.0, 0.2, 1.5)
        dev.request_gains()
        assert wait_until(lambda: dev.controller_gains is not None)
        s = fake.snapshot()
        assert s.sound_sequences == [4] and s.sounds[0][1] == 100
        assert s.leds == {"led1": "orange", "led2": "green"}
        assert s.gp_output & 0x00F0 == 0x00F0  # power rails kept on
        assert dev.controller_gains == k.ControllerInfo(True, 90.0, 0.2, 1.5)
    finally:
        dev.close()


def test_fake_counts_bad_checksum_commands(fake: KobukiFake, wait_until: Waiter) -> None:
    frame = k.encode_frame(k.base_control(100, 0))
    with SerialTransport(SerialSettings(fake.port)) as link:
        link.write(frame[:-1] + bytes((frame[-1] ^ 1,)))
        assert wait_until(lambda: fake.snapshot().bad_command_frames == 1)
        assert fake.snapshot().speed == 0
        link.write(frame)
        assert wait_until(lambda: fake.snapshot().speed == 100)


def test_base_refuses_before_connect() -> None:
    base = KobukiBase(KobukiDevice(KobukiConfig(port="/dev/null")))
    with pytest.raises(CapabilityError, match="call connect"):
        base.set_velocity(0.1, 0.0)


def test_config_rejects_limits_above_spec() -> None:
    with pytest.raises(ValueError, match="max_linear"):
        KobukiDevice(KobukiConfig(port="/dev/x", max_linear=1.0))
