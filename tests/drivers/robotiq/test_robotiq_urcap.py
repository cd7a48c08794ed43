"""The URCap socket variant (TCP 63352 text protocol) against the loopback fake."""

from __future__ import annotations

import socket
from collections.abc import Iterator

import pytest
from robotiq_helpers import finish, wait_for

from mmexec.drivers.fakes.robotiq import FakeURCap
from mmexec.drivers.interfaces import GoalState, GraspState
from mmexec.drivers.robotiq import codec
from mmexec.drivers.robotiq.codec import Command
from mmexec.drivers.robotiq.core import LinkState
from mmexec.drivers.robotiq.errors import RobotiqNotReady, RobotiqTimeout
from mmexec.drivers.robotiq.gripper import RobotiqGripper
from mmexec.drivers.robotiq.urcap import RobotiqURCap, URCapSettings, encode_set, parse_get_reply


@pytest.fixture
def server() -> Iterator[FakeURCap]:
    with FakeURCap(activation_time=0.2, time_scale=10.0) as s:
        yield s


def make(server: FakeURCap) -> RobotiqGripper:
    return RobotiqGripper(RobotiqURCap(URCapSettings("127.0.0.1", server.port,
                                                     reply_timeout=0.1)))


def ask(sock: socket.socket, line: str) -> str:
    sock.sendall(line.encode() + b"\n")
    buf = b""
    while not buf.endswith(b"\n"):
        chunk = sock.recv(100)
        assert chunk
        buf += chunk
    return buf.decode().strip()


def test_text_protocol_raw(server: FakeURCap) -> None:
    with socket.create_connection(("127.0.0.1", server.port), timeout=1.0) as sock:
        assert ask(sock, "GET STA") == "STA 0"
        assert ask(sock, "SET ACT 1") == "ack"
        assert ask(sock, "GET STA") == "STA 1"
        assert wait_for(lambda: ask(sock, "GET STA") == "STA 3", 1.0)
        assert ask(sock, "SET POS 100 SPE 255 FOR 50 GTO 1") == "ack"
        assert ask(sock, "GET PRE") == "PRE 100"
        assert wait_for(lambda: ask(sock, "GET OBJ") == "OBJ 3", 1.0)
        assert ask(sock, "GET POS") == "POS 100"
        assert ask(sock, "SET POS 300") == "nack"
        server.estop = True
        assert ask(sock, "GET FLT") == "FLT ?"
        assert ask(sock, "GET POS") == "POS ?"


def test_codec_helpers() -> None:
    assert encode_set(Command(rACT=True, rGTO=True, rPR=10, rSP=20, rFR=30)) == \
        b"SET ACT 1 ATR 0 ARD 0 POS 10 SPE 20 FOR 30 GTO 1\n"
    assert parse_get_reply("OBJ", "OBJ 2") == 2
    assert parse_get_reply("OBJ", "OBJ ?") is None
    with pytest.raises(ValueError, match="expected 'OBJ <int>'"):
        parse_get_reply("OBJ", "ack")


def test_activate_move_and_object(server: FakeURCap) -> None:
    g = make(server)
    try:
        act = g.setup()
        assert act is not None and finish(act) is GoalState.SUCCEEDED
        assert server.requests.count("SET ACT 0 ATR 0 ARD 0 POS 0 SPE 0 FOR 0 GTO 0") == 1
        goal = g.move(0.04, speed=0.15, force=80.0)
        assert finish(goal) is GoalState.SUCCEEDED
        assert goal.result.width == pytest.approx(0.04, abs=codec.STROKE / 255)
        assert goal.result.grasp is GraspState.AT_POSITION
        server.model.object_width = 0.02
        goal = g.close(speed=0.15)
        assert finish(goal) is GoalState.SUCCEEDED
        assert goal.result.grasp is GraspState.CONTACT_CLOSING
        server.model.drop_object()
        assert wait_for(lambda: g.state().grasp is GraspState.DROPPED, 1.0)
    finally:
        g.disconnect()


def test_estop_fails_goal_and_recovers(server: FakeURCap) -> None:
    g = make(server)
    try:
        act = g.setup()
        assert act is not None and finish(act) is GoalState.SUCCEEDED
        server.model.time_scale = 1.0
        goal = g.close(speed=0.02)
        server.estop = True
        assert finish(goal, 1.0) is GoalState.FAILED
        assert "emergency-stopped (URCap answered" in goal.reason
        assert g.device.link_state is LinkState.ESTOP
        with pytest.raises(RobotiqNotReady, match="release the e-stop first"):
            g.open()
        server.estop = False
        assert wait_for(lambda: g.device.link_state is LinkState.CONNECTED, 1.0)
        assert finish(g.open(speed=0.15), 3.0) is GoalState.SUCCEEDED
    finally:
        g.disconnect()


def test_silent_controller_times_out(server: FakeURCap) -> None:
    g = make(server)
    try:
        act = g.setup()
        assert act is not None and finish(act) is GoalState.SUCCEEDED
        server.model.time_scale = 1.0
        goal = g.close(speed=0.02)
        server.silent = True
        assert finish(goal, 1.5) is GoalState.FAILED
        assert "no answer within the deadline (100 ms)" in goal.reason
        assert "(3 tries)" in goal.reason
    finally:
        g.disconnect()
    server.silent = True
    dev = RobotiqURCap(URCapSettings("127.0.0.1", server.port, reply_timeout=0.1))
    with pytest.raises(RobotiqTimeout, match="no answer within the deadline"):
        dev.open()


def test_connection_dropped(server: FakeURCap) -> None:
    g = make(server)
    try:
        g.setup(activate=False)
        server.drop_clients()
        assert wait_for(lambda: g.device.link_state is LinkState.LOST, 1.0)
        assert "link lost" in g.state().fault
        g.device.reconnect()
        assert finish(g.activate()) is GoalState.SUCCEEDED
    finally:
        g.disconnect()


def test_close_waits_for_one_round_trip_not_a_whole_status_read(server: FakeURCap) -> None:
    # a status read through the URCap is seven GETs; with a slow controller close() must
    # not wait for all of them: no request is sent after close() began
    dev = RobotiqURCap(URCapSettings("127.0.0.1", server.port, reply_timeout=0.5))
    dev.open()
    server.answer_delay = 0.05
    n = len(server.requests)
    assert wait_for(lambda: len(server.requests) >= n + 2, 2.0)   # a read is under way
    at_close = len(server.requests)
    dev.close()
    assert len(server.requests) <= at_close + 1
