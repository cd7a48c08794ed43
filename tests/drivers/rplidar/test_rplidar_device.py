"""RplidarDevice and RplidarLidar against the protocol fake on a pty: identity, scan
geometry (CCW), every fault switch, STOP and motor off on close."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator

import numpy as np
import pytest

from mmexec.drivers.fakes.rplidar import RplidarFake
from mmexec.drivers.interfaces import LaserScan, ManualClock
from mmexec.drivers.rplidar.device import (
    DeviceState,
    RplidarConfig,
    RplidarCorruptStream,
    RplidarDevice,
    RplidarHealthError,
    RplidarLinkLost,
    RplidarMotorError,
    RplidarNotConnected,
    RplidarPortError,
    RplidarTimeout,
    RplidarWatchdog,
    ScanFault,
)
from mmexec.drivers.rplidar.lidar import RplidarLidar

Waiter = Callable[..., bool]
STOP, SCAN, SET_PWM = 0x25, 0x20, 0xF0


def _device(fake: RplidarFake, clock: ManualClock | None = None, **kw: object) -> RplidarDevice:
    return RplidarDevice(RplidarConfig(port=fake.port, **kw), clock)  # type: ignore[arg-type]


@pytest.fixture
def scanning(fake: RplidarFake, wait_until: Waiter) -> Iterator[RplidarDevice]:
    """A connected device streaming complete scans."""
    dev = _device(fake)
    dev.connect()
    dev.start()
    try:
        assert wait_until(lambda: dev.latest_scan() is not None)
        yield dev
    finally:
        dev.close()


def _range_at(scan: LaserScan, angle: float) -> float:
    """Range [m] of the beam nearest to the CCW ``angle`` [rad] in the lidar frame."""
    i = int(np.argmin(np.abs(np.angle(np.exp(1j * (scan.angles - angle))))))
    return float(scan.ranges[i])


def _intensity_at(scan: LaserScan, angle: float) -> float:
    assert scan.intensities is not None
    i = int(np.argmin(np.abs(np.angle(np.exp(1j * (scan.angles - angle))))))
    return float(scan.intensities[i])


# --------------------------------------------------------------------------- nominal


def test_connect_reads_identity_health_and_motor_control(fake: RplidarFake) -> None:
    dev = _device(fake)
    try:
        info = dev.connect()
        assert info.device.model_name == "A2M8" and info.device.firmware == "1.29"
        assert info.device.hardware == 7 and info.device.serial_text == "101112131415161718191A1B1C1D1E1F"
        assert info.health.status.name == "GOOD" and info.sample_rate.standard_us == 500
        assert info.motor_pwm_supported and not info.dtr            # a pty has no DTR line
        assert dev.state is DeviceState.IDLE and dev.latest_scan() is None
        snap = fake.snapshot()
        assert snap.requests[0] == STOP and SCAN not in snap.requests and not fake.motor_running
    finally:
        dev.close()
    assert dev.state is DeviceState.CLOSED


def test_walls_and_posts_appear_at_their_ccw_angles_and_ranges(fake: RplidarFake, wait_until: Waiter) -> None:
    clock = ManualClock(100.0)
    dev = _device(fake, clock)
    dev.connect()
    lidar = RplidarLidar(dev)
    try:
        dev.start()
        assert wait_until(lambda: lidar.scan() is not None)
        scan = lidar.scan()
        assert scan is not None and scan.stamp == 100.0 and len(scan.ranges) == 360
        assert scan.angle_min == -math.pi and scan.angle_increment == pytest.approx(2 * math.pi / 360)
        # the lidar at (2.0, 1.5) of the 6 x 4 m room, its 0 deg along the room's +x:
        # east wall straight ahead, north wall to the LEFT (+pi/2, CCW), south to the right
        assert _range_at(scan, 0.0) == pytest.approx(4.0, abs=0.03)
        assert _range_at(scan, math.pi / 2) == pytest.approx(2.5, abs=0.03)
        assert _range_at(scan, -math.pi / 2) == pytest.approx(1.5, abs=0.03)
        assert _range_at(scan, math.pi) == pytest.approx(2.0, abs=0.03)
        # reflector posts (r 0.05) at (1, 1) and (5, 3); a plain post (r 0.1) at (4.5, 1)
        for (px, py, r), reflector in (((1.0, 1.0, 0.05), True), ((5.0, 3.0, 0.05), True),
                                       ((4.5, 1.0, 0.1), False)):
            angle = math.atan2(py - 1.5, px - 2.0)
            assert _range_at(scan, angle) == pytest.approx(math.hypot(px - 2.0, py - 1.5) - r, abs=0.03)
            assert (_intensity_at(scan, angle) == 1.0) is reflector
        assert np.isfinite(scan.ranges).all()                       # a closed room: every beam returns
        clock.advance(5.0)
        assert wait_until(lambda: (s := lidar.scan()) is not None and s.stamp == 105.0)
    finally:
        lidar.close()


def test_a_turned_lidar_sees_the_room_turned_the_other_way(fake: RplidarFake, wait_until: Waiter) -> None:
    fake.pose = (2.0, 1.5, math.pi / 2)   # the lidar's 0 deg now faces north
    dev = _device(fake)
    dev.connect()
    try:
        dev.start()
        assert wait_until(lambda: dev.latest_scan() is not None and dev.stats().scans >= 2)
        scan = dev.latest_scan()
        assert scan is not None
        assert _range_at(scan, 0.0) == pytest.approx(2.5, abs=0.03)           # north ahead
        assert _range_at(scan, -math.pi / 2) == pytest.approx(4.0, abs=0.03)  # east on the right
    finally:
        dev.close()


def test_close_sends_stop_and_switches_the_motor_off(scanning: RplidarDevice, fake: RplidarFake,
                                                      wait_until: Waiter) -> None:
    assert fake.snapshot().scanning and fake.motor_running
    stops = fake.snapshot().stops
    scanning.close()
    # the fake reads in its own thread: wait (bounded) for it to have seen both requests
    assert wait_until(lambda: fake.snapshot().requests[-2:] == [STOP, SET_PWM], 1.0)
    snap = fake.snapshot()
    assert snap.stops == stops + 1 and not snap.scanning
    assert snap.pwm_commands[-1] == 0 and snap.pwm == 0 and not fake.motor_running
    assert scanning.state is DeviceState.CLOSED and scanning.latest_scan() is None


def test_stop_then_start_again(scanning: RplidarDevice, fake: RplidarFake, wait_until: Waiter) -> None:
    scanning.stop()
    assert scanning.state is DeviceState.IDLE and scanning.latest_scan() is None
    assert wait_until(lambda: not fake.motor_running, 1.0)
    scanning.start()
    assert wait_until(lambda: scanning.latest_scan() is not None)
    assert scanning.fault is None


def test_stats_measure_rate_and_points(scanning: RplidarDevice, wait_until: Waiter) -> None:
    assert wait_until(lambda: scanning.stats().scans >= 6)
    st = scanning.stats(window=1.0)
    # the fake turns at 10 Hz of wall time: a loose bound (arrival times jitter under load)
    assert st.scan_rate is not None and 5.0 < st.scan_rate < 20.0
    assert st.points_per_scan == pytest.approx(200, abs=2)   # 2000 samples/s at 10 Hz
    assert st.rejected <= 1 and st.corrupt_bytes == 0


# --------------------------------------------------------------------------- refusals at connect


def test_health_error_is_refused_before_the_motor_starts(fake: RplidarFake) -> None:
    fake.set_health(2, 0x1234)
    dev = _device(fake)
    with pytest.raises(RplidarHealthError, match=r"rplidar on .*: health ERROR \(error code 0x1234\)"):
        dev.connect()
    assert dev.state is DeviceState.CLOSED
    snap = fake.snapshot()
    assert SCAN not in snap.requests and snap.pwm_commands == [] and not fake.motor_running


def test_health_warning_is_accepted(fake: RplidarFake) -> None:
    fake.set_health(1, 0x0012)
    dev = _device(fake)
    try:
        assert dev.connect().health.error_code == 0x0012
    finally:
        dev.close()


@pytest.mark.parametrize("switch, error, text", [
    ("silent", RplidarTimeout, "no answer to GET_INFO within 0.3 s"),
    ("garbage", RplidarCorruptStream, "no valid answer to GET_INFO within 0.3 s"),
])
def test_a_silent_or_noisy_line_is_one_typed_error(fake: RplidarFake, switch: str, error: type,
                                                   text: str) -> None:
    setattr(fake, switch, True)
    dev = _device(fake, response_timeout=0.3)
    with pytest.raises(error) as ei:
        dev.connect()
    assert str(ei.value).startswith(f"rplidar on {fake.port}: {text}")
    assert dev.state is DeviceState.CLOSED


def test_no_such_port() -> None:
    dev = RplidarDevice(RplidarConfig(port="/dev/does-not-exist-rplidar"))
    with pytest.raises(RplidarPortError, match="rplidar on /dev/does-not-exist-rplidar: no such port"):
        dev.connect()


def test_start_needs_connect_and_a_motor(fake: RplidarFake) -> None:
    dev = _device(fake)
    with pytest.raises(RplidarNotConnected, match=r"call connect\(\) first"):
        dev.start()
    fake.motor_control = False   # no SET_MOTOR_PWM, and a pty has no DTR line
    dev.connect()
    try:
        assert not dev.info().motor_pwm_supported  # type: ignore[union-attr]
        with pytest.raises(RplidarMotorError, match="no DTR line"):
            dev.start()
        assert SCAN not in fake.snapshot().requests
    finally:
        dev.close()


def test_config_rejects_bad_values() -> None:
    with pytest.raises(ValueError) as ei:
        RplidarDevice(RplidarConfig(baudrate=9600, motor_pwm=2000, beams=4, min_scan_rate=0.0))
    for key in ("baudrate", "motor_pwm", "beams", "min_scan_rate"):
        assert key in str(ei.value)
    assert RplidarConfig().watchdog_timeout == pytest.approx(0.6)   # 3 revolutions at 5 Hz


# --------------------------------------------------------------------------- faults while scanning


@pytest.mark.parametrize("switch, value, cause", [
    ("motor_stopped", True, ScanFault.NO_DATA),
    ("silent", True, ScanFault.NO_DATA),
    ("garbage", True, ScanFault.CORRUPT),
    ("no_start_flag", True, ScanFault.NO_START_FLAG),
    ("bad_check_bits", 1.0, ScanFault.CORRUPT),
    ("bad_start_bits", 1.0, ScanFault.CORRUPT),
    ("truncate", 1.0, ScanFault.CORRUPT),
])
def test_every_stream_fault_trips_the_watchdog_and_clears(
    scanning: RplidarDevice, fake: RplidarFake, wait_until: Waiter, switch: str, value: object,
    cause: ScanFault,
) -> None:
    lidar = RplidarLidar(scanning)
    deadline = scanning.config.watchdog_timeout
    setattr(fake, switch, value)
    assert wait_until(lambda: scanning.fault is not None, deadline + 3.0)
    fault = scanning.fault
    assert isinstance(fault, RplidarWatchdog) and fault.cause is cause, fault
    # what the device saw: the fault was raised at the watchdog deadline (generous upper
    # bound: the reader thread and this poll may be scheduled late on a loaded machine)
    assert deadline <= fault.seconds < deadline + 2.0
    assert str(fault).startswith(f"rplidar on {fake.port}: no complete scan for ")
    assert scanning.latest_scan() is None and lidar.scan() is None and lidar.fault is fault
    setattr(fake, switch, type(value)())   # False / 0.0: the fault goes away
    assert wait_until(lambda: lidar.scan() is not None, 3.0)
    assert scanning.fault is None


def test_sparse_corruption_is_survived(scanning: RplidarDevice, fake: RplidarFake, wait_until: Waiter) -> None:
    fake.bad_check_bits, fake.truncate = 0.03, 0.01
    scans = scanning.stats().scans
    assert wait_until(lambda: scanning.stats().scans >= scans + 5)
    assert scanning.fault is None and scanning.stats().corrupt_bytes > 0
    scan = scanning.latest_scan()
    assert scan is not None
    assert float(np.nanmedian(scan.ranges[170:190])) == pytest.approx(4.0, abs=0.05)  # east wall


def test_unplug_is_link_lost_latched(scanning: RplidarDevice, fake: RplidarFake, wait_until: Waiter) -> None:
    fake.unplug()
    assert wait_until(lambda: isinstance(scanning.fault, RplidarLinkLost), 3.0)
    assert scanning.state is DeviceState.LOST and scanning.latest_scan() is None
    assert str(scanning.fault).startswith(f"rplidar on {fake.port}: link failed")
    scanning.close()   # the port is gone: close logs and does not raise
    assert scanning.state is DeviceState.CLOSED


def test_lidar_adds_its_mount(scanning: RplidarDevice) -> None:
    T = np.eye(4)
    T[:3, 3] = (-0.1, 0.0, 0.64)
    T[:2, :2] = [[-1.0, 0.0], [0.0, -1.0]]   # yawed by pi
    scan = RplidarLidar(scanning, T).scan()
    assert scan is not None and np.array_equal(scan.T_base_lidar, T)
    with pytest.raises(ValueError, match="4x4"):
        RplidarLidar(scanning, np.eye(3))
