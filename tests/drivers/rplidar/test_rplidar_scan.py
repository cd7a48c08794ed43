"""One revolution of nodes into the CCW grid: angles, inf / nan, intensity, acceptance."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mmexec.drivers.rplidar.codec import MeasurementNode
from mmexec.drivers.rplidar.scan import (
    MIN_POINTS,
    Revolution,
    RevolutionAssembler,
    check_revolution,
    drop_out_of_order,
    resample,
)


def _turn(n: int, dist_q2: int = 8000, quality: int = 40) -> list[MeasurementNode]:
    """``n`` evenly spaced nodes over one clockwise turn from 0 deg."""
    return [MeasurementNode(i == 0, quality, round(i * 360 * 64 / n), dist_q2) for i in range(n)]


def _at(scan_angle: float, beams: int) -> int:
    """Bin index of a CCW angle [rad]."""
    return round((scan_angle + math.pi) / (2 * math.pi / beams)) % beams


def test_clockwise_device_angle_lands_in_the_ccw_bin() -> None:
    nodes = _turn(200)
    # one object 90 deg clockwise (to the right): 1.5 m, quality 63
    i90 = 50
    nodes[i90] = MeasurementNode(False, 63, 90 * 64, 6000)
    ranges, intensity = resample(nodes, 360)
    right = _at(-math.pi / 2, 360)
    assert ranges[right] == pytest.approx(1.5) and intensity[right] == pytest.approx(1.0)
    left = _at(math.pi / 2, 360)
    assert ranges[left] == pytest.approx(2.0) and intensity[left] == pytest.approx(40 / 63)
    assert not np.isnan(ranges).any()


def test_no_return_is_inf_and_a_gap_is_nan() -> None:
    nodes = [n for n in _turn(200) if not 20 <= n.angle_q6 / 64 <= 40]  # 20 deg not measured
    nodes[10] = MeasurementNode(False, 0, nodes[10].angle_q6, 0)        # one without a return
    ranges, intensity = resample(nodes, 360)
    no_return = _at(-math.radians(nodes[10].angle_q6 / 64), 360)
    assert ranges[no_return] == math.inf and intensity[no_return] == 0.0
    gap = _at(-math.radians(30), 360)
    assert math.isnan(ranges[gap]) and intensity[gap] == 0.0
    assert "deg gap" in check_revolution(nodes)  # 18.0 to 41.4 deg: not a complete scan


def test_more_bins_than_nodes_fill_from_the_nearest_node() -> None:
    ranges, _ = resample(_turn(100), 720)  # 3.6 deg per node, 0.5 deg per bin
    assert not np.isnan(ranges).any() and ranges == pytest.approx(np.full(720, 2.0))


def test_revolution_acceptance() -> None:
    assert check_revolution(_turn(200)) == ""
    assert "fewer than" in check_revolution(_turn(MIN_POINTS - 1))
    assert "corrupt" in check_revolution(_turn(200), corrupt_bytes=400)
    assert check_revolution(_turn(200), corrupt_bytes=50) == ""


def test_an_isolated_out_of_order_node_is_dropped() -> None:
    nodes = _turn(100)
    bogus = MeasurementNode(False, 10, 300 * 64, 123)
    mixed = [*nodes[:40], bogus, *nodes[40:]]
    assert drop_out_of_order(mixed) == nodes
    # jitter across the start (359.9 deg then 0.1 deg) is no disorder
    wrap = [MeasurementNode(True, 40, 5, 8000), *nodes[1:], MeasurementNode(False, 40, 360 * 64 - 3, 8000)]
    assert drop_out_of_order(wrap) == wrap


def _stream(turns: int, n: int = 200) -> list[MeasurementNode]:
    """``turns`` clean revolutions of ``n`` nodes, the start flag on each turn's first."""
    return [node for _ in range(turns) for node in _turn(n)]


def _assemble(nodes: list[MeasurementNode]) -> list[Revolution]:
    asm = RevolutionAssembler()
    out = [asm.push(0, node, float(i)) for i, node in enumerate(nodes)]
    return [r for r in out if r is not None]


def test_revolutions_are_cut_at_start_flags() -> None:
    revs = _assemble(_stream(4))
    # the fourth turn is still open; the first starts at the first node
    assert [len(r.nodes) for r in revs] == [200, 200, 200]
    assert [r.stamp for r in revs] == [0.0, 200.0, 400.0]
    assert all(r.nodes[0].start and r.travel_q6 == _turn(200)[-1].angle_q6 for r in revs)  # 358.2 deg
    assert all(check_revolution(r.nodes, r.corrupt_bytes, r.travel_q6) == "" for r in revs)


def test_a_start_flag_out_of_turn_is_not_believed() -> None:
    nodes = _stream(3)
    # mid-turn, a misaligned window that passed the checks with S = 1 at a random angle,
    # and one with S = 1 right in sequence (its angle fits, but the turn is half done)
    nodes[300] = MeasurementNode(True, 7, 17 * 64, 999)
    nodes[350] = MeasurementNode(True, 40, nodes[350].angle_q6, 8000)
    asm = RevolutionAssembler()
    revs = [r for i, n in enumerate(nodes) if (r := asm.push(0, n, float(i))) is not None]
    assert [len(r.nodes) for r in revs] == [200, 198]
    assert asm.bogus_starts == 2 and revs[1].corrupt_bytes == 10


def test_a_lost_start_flag_gives_two_turns_which_are_refused() -> None:
    nodes = _stream(4)
    nodes[200] = MeasurementNode(False, 40, nodes[200].angle_q6, 8000)   # its S bit lost
    revs = _assemble(nodes)
    assert [len(r.nodes) for r in revs] == [400, 200]
    assert "start flag lost" in check_revolution(revs[0].nodes, 0, revs[0].travel_q6)
    assert check_revolution(revs[1].nodes, 0, revs[1].travel_q6) == ""
