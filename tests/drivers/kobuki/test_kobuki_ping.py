"""``mmexec hw ping kobuki`` against the protocol fake: 0 ready, 1 answered but not fit to
run (or no useful answer), 2 bad input or the port cannot be opened; link quality on the
report line and a warning above 1 %."""

from __future__ import annotations

import threading

import pytest

from mmexec.drivers import hwcli
from mmexec.drivers.fakes.kobuki import KobukiFake

Capture = pytest.CaptureFixture[str]


def _ping(capsys: Capture, *args: str) -> tuple[int, str, str]:
    rc = hwcli.main(["ping", "kobuki", *args])
    out = capsys.readouterr()
    assert "Traceback" not in out.err
    return rc, out.out.strip(), out.err.strip()


def _one_line(text: str) -> str:
    assert len(text.splitlines()) == 1, text
    return text


def test_ready_base_exits_0_with_link_quality(fake: KobukiFake, capsys: Capture) -> None:
    rc, out, err = _ping(capsys, "--port", fake.port)
    assert rc == 0 and err == ""
    line = _one_line(out)
    assert line.startswith(f"kobuki on {fake.port}: firmware 1.2.0, hardware 1.0.4, battery 16.5 V, unique id ")
    assert "; link: " in line and " 0 corrupt, 0 lost, " in line and "over 1.0 s" in line
    assert fake.snapshot().moving_commands == 0  # never moves the base


@pytest.mark.parametrize(
    ("fault", "text"),
    [("bumper_left", "bumper pressed"), ("bumper_centre", "bumper pressed"),
     ("cliff_right", "cliff (a wheel over an edge)"), ("wheel_drop_left", "wheel dropped"),
     ("overcurrent_left", "motor overcurrent"), ("overcurrent_right", "motor overcurrent")],
)
def test_base_that_answers_but_is_not_fit_exits_1(fake: KobukiFake, capsys: Capture, fault: str, text: str) -> None:
    fake.set_fault(fault)
    rc, out, err = _ping(capsys, "--port", fake.port, "--duration", "0.3")
    assert rc == 1
    assert out.startswith(f"kobuki on {fake.port}: firmware 1.2.0")  # it did answer
    assert _one_line(err) == f"kobuki on {fake.port}: not fit to run: {fault} ({text})"


def test_fault_raised_during_the_ping_is_seen(fake: KobukiFake, capsys: Capture) -> None:
    timer = threading.Timer(0.2, fake.set_fault, ("wheel_drop_right",))
    timer.start()
    try:
        rc, _, err = _ping(capsys, "--port", fake.port, "--duration", "0.8")
    finally:
        timer.cancel()
    assert rc == 1 and "wheel_drop_right (wheel dropped)" in _one_line(err)


def test_link_lost_during_the_ping_exits_1(fake: KobukiFake, capsys: Capture) -> None:
    timer = threading.Timer(0.2, setattr, (fake, "mute", True))
    timer.start()
    try:
        rc, _, err = _ping(capsys, "--port", fake.port, "--duration", "0.8")
    finally:
        timer.cancel()
    assert rc == 1 and "link_lost (link lost during the ping)" in _one_line(err)


@pytest.mark.parametrize("kind", ["corrupt", "lost"])
def test_poor_link_warns_above_one_percent_but_is_ready(fake: KobukiFake, capsys: Capture, kind: str) -> None:
    if kind == "corrupt":
        fake.corrupt_stream(every=10)
    else:
        fake.drop_stream(every=10)
    rc, out, err = _ping(capsys, "--port", fake.port)
    assert rc == 0
    assert "0 corrupt" not in out if kind == "corrupt" else "0 lost" not in out
    line = _one_line(err)
    assert line.startswith(f"kobuki on {fake.port}: warning: link quality ")
    assert "above 1 %" in line


def test_only_corrupt_frames_exits_1(fake: KobukiFake, capsys: Capture) -> None:
    fake.corrupt_stream()
    rc, out, err = _ping(capsys, "--port", fake.port, "--timeout", "0.2")
    assert rc == 1 and out == ""
    assert _one_line(err).startswith(f"kobuki on {fake.port}: corrupt frames")


def test_silent_base_exits_1(fake: KobukiFake, capsys: Capture) -> None:
    fake.silent = True
    rc, _, err = _ping(capsys, "--port", fake.port, "--timeout", "0.2")
    assert rc == 1
    assert _one_line(err) == f"kobuki on {fake.port}: no answer within 0.2 s (is the base switched on?)"


def test_firmware_2_exits_1(fake: KobukiFake, capsys: Capture) -> None:
    fake.set_firmware(2, 0, 0)
    rc, _, err = _ping(capsys, "--port", fake.port)
    assert rc == 1 and "firmware 2.0.0 is not supported" in _one_line(err)


def test_port_that_cannot_be_opened_exits_2(capsys: Capture) -> None:
    rc, out, err = _ping(capsys, "--port", "/dev/no-kobuki-here")
    assert rc == 2 and out == ""
    assert _one_line(err).startswith("kobuki on /dev/no-kobuki-here: no such port")


@pytest.mark.parametrize(("option", "value"), [("--timeout", "0"), ("--timeout", "inf"), ("--duration", "nan"),
                                               ("--duration", "-1"), ("--duration", "1e9")])
def test_bad_option_values_exit_2(capsys: Capture, option: str, value: str) -> None:
    rc, _, err = _ping(capsys, "--port", "/dev/kobuki", option, value)
    assert rc == 2
    assert _one_line(err).startswith(f"kobuki on /dev/kobuki: {option} must be a number of seconds")


def test_timeout_below_one_frame_period_exits_2(capsys: Capture) -> None:
    rc, _, err = _ping(capsys, "--port", "/dev/kobuki", "--timeout", "0.01")
    assert rc == 2
    line = _one_line(err)
    assert line.startswith("kobuki on /dev/kobuki: connect_timeout: must be 0.02..60 s") and "--timeout 0.01" in line
