"""Our pure-Python RTDE client: link quality arithmetic, and a session against the RTDE
local_stub process (on an ephemeral port) with each of its fault switches."""

from __future__ import annotations

import threading
import time

import pytest
from urtest_helpers import wait_for

from mmexec.drivers.ur.rtde_client import (
    RTDEClientError,
    RTDESession,
    RTDEUnreachable,
    link_quality,
    probe,
)
from mmexec.drivers.ur.rtde_stub import RTDEStub

VARS = ("timestamp", "actual_q", "robot_mode", "safety_mode", "safety_status_bits", "runtime_state")


def test_link_quality_counts_timestamp_gaps_and_late_delivery() -> None:
    period = 0.002
    stamps = [k * period for k in range(10)]
    clean = link_quality(stamps, [100.0 + s for s in stamps], period, 0.01)
    assert (clean.frames, clean.lost, clean.late, clean.ratio) == (10, 0, 0, 0.0)
    assert clean.duration == pytest.approx(0.018)
    # samples 3 and 6, 7 never arrived: gaps of 2 and 3 periods
    kept = [s for k, s in enumerate(stamps) if k not in (3, 6, 7)]
    stats = link_quality(kept, [100.0 + s for s in kept], period, 0.01)
    assert (stats.frames, stats.lost, stats.late) == (7, 3, 0)
    assert stats.ratio == pytest.approx(3 / 10)
    # a burst: samples 2..5 held back and delivered together with sample 6
    arrivals = [100.0 + (stamps[6] + 0.02 if 2 <= k <= 5 else s) for k, s in enumerate(stamps)]
    stats = link_quality(stamps, arrivals, period, 0.01)
    assert (stats.lost, stats.late) == (0, 4)
    assert str(stats) == "10 frames, 0 lost, 4 late over 0.0 s (40.0 %)"
    assert link_quality([], [], period, 0.01).ratio == 0.0
    with pytest.raises(ValueError, match="2 stamps but 1 arrival"):
        link_quality([0.0, 0.002], [1.0], period, 0.01)


def test_probe_reads_version_and_state(local_stub: RTDEStub) -> None:
    local_stub.set_state(robot_mode=5, safety_mode=2, runtime_state=1)
    snap = probe(RTDESession(local_stub.host, local_stub.port, 2.0), VARS)
    assert str(snap.version) == "5.15.0.12345"
    v = snap.values
    assert (v["robot_mode"], v["safety_mode"], v["safety_status_bits"], v["runtime_state"]) == (5, 2, 1 << 1, 1)


@pytest.mark.parametrize(
    ("switch", "reason"),
    [
        (lambda s: s.silence(0), "no answer within 0.3 s (waiting for 'V')"),
        (lambda s: s.garbage(True),
         "corrupt RTDE reply (unknown package type 110 (0x6e) at offset 0): not an RTDE server?"),
        (lambda s: s.set_not_found(["safety_status_bits"]), "controller answered NOT_FOUND for safety_status_bits"),
    ],
    ids=["silent", "garbage", "not_found"],
)
def test_a_peer_that_answers_wrongly_is_one_line(local_stub: RTDEStub, switch, reason: str) -> None:  # type: ignore[no-untyped-def]
    switch(local_stub)
    with pytest.raises(RTDEClientError) as e:
        probe(RTDESession(local_stub.host, local_stub.port, 0.3), VARS)
    assert not isinstance(e.value, RTDEUnreachable)
    assert str(e.value) == f"{local_stub.host}:{local_stub.port}: {reason}"


def test_refused_is_unreachable() -> None:
    with RTDEStub("127.0.0.1", 0) as s:
        s.refuse_connections(True)
        with pytest.raises(RTDEUnreachable) as e:
            probe(RTDESession(s.host, s.port, 1.0), VARS)
    assert e.value.detail == "connection refused (is the controller on and RTDE enabled?)"


def test_abort_ends_a_wait_from_another_thread(local_stub: RTDEStub) -> None:
    local_stub.silence(0)
    session = RTDESession(local_stub.host, local_stub.port, 600.0)  # only abort() can end the wait
    errors: list[RTDEClientError] = []

    def run() -> None:
        try:
            probe(session, VARS)
        except RTDEClientError as e:
            errors.append(e)

    t = threading.Thread(target=run, daemon=True)
    t.start()
    assert wait_for(lambda: local_stub.stats()["clients"] >= 1, 30.0)
    session.abort()
    t.join(30.0)
    assert not t.is_alive()
    assert [e.detail for e in errors] == ["aborted"]


def test_deadline_caps_every_step(local_stub: RTDEStub) -> None:
    local_stub.silence(0)
    with pytest.raises(RTDEClientError, match=r"no answer within 0\.[0-9] s \(waiting for 'V'\)"):
        probe(RTDESession(local_stub.host, local_stub.port, 600.0, deadline=time.monotonic() + 0.5), VARS)
