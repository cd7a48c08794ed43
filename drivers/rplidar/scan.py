"""RPLIDAR measurement nodes into revolutions, and a revolution into a fixed-grid scan
(pure: no I/O, no clocks; numpy).

:class:`RevolutionAssembler` cuts the node stream at start flags. The node checks are
two bits, so a misaligned window after a corrupt or truncated node passes them one time
in four, and one time in two of those it carries S = 1. A start flag therefore counts
only when it is credible: its angle follows the previous node's and precedes the next
node's clockwise within :data:`MAX_GAP` (a new revolution continues the turn), and the
revolution it closes has turned through at least 360 deg - :data:`MAX_GAP` (steps wider
than :data:`MAX_GAP` do not count); other start nodes are dropped as corrupt. (Derived
from "S = 1 on the first node of a new revolution" and the clockwise order of the
angles.) A real start refused because corruption hid part of the turn ends the
revolution one turn later; :func:`check_revolution` judges what that gives.

The device samples at irregular angles (clockwise, about 200 per revolution in standard
scan at 10 Hz); :class:`~mmexec.drivers.interfaces.LaserScan` is a regular grid of CCW
angles. :func:`check_revolution` decides whether a revolution is complete and sane, and
:func:`resample` puts it on the grid:

* angles become counter-clockwise in the lidar frame: ``a = -angle_device``, wrapped to
  [-pi, pi); bin ``i`` is centred on ``-pi + i * 2 pi / beams``;
* each bin takes the node nearest in angle to its centre when that node lies within
  0.75 of the revolution's median node spacing (or half a bin, whichever is larger);
  a bin no node reaches is ``nan`` (not measured in this revolution, e.g. nodes lost to
  corruption), a node without a return (distance 0) gives ``inf``;
* intensity is the node's quality / 63 (0 no return, 1 retro-reflector), 0 where ``nan``.

A revolution is accepted when it turned once (a lost start flag gives two turns), has at
least :data:`MIN_POINTS` and at most :data:`MAX_POINTS` nodes, no gap wider
than :data:`MAX_GAP` between neighbouring angles, and at most :data:`MAX_CORRUPT_FRACTION`
of its bytes thrown away; isolated nodes whose angle breaks the clockwise order of their
neighbours (a misaligned window that passed the two check bits) are dropped first. The
byte share matters because the node checks are two bits: a stream that loses a byte per
node still yields nodes at plausible angles, with garbage ranges.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from mmexec.drivers.geometry import wrap_angle
from mmexec.drivers.rplidar.codec import NODE_SIZE, MeasurementNode

__all__ = [
    "MAX_CORRUPT_FRACTION",
    "MAX_GAP",
    "MAX_POINTS",
    "MIN_POINTS",
    "Revolution",
    "RevolutionAssembler",
    "check_revolution",
    "drop_out_of_order",
    "resample",
]

#: fewest nodes in a complete revolution (standard scan at 15 Hz gives about 130)
MIN_POINTS = 50
#: a revolution growing past this many nodes has lost its start flags (the A2 samples at
#: most 8000/s and turns at least 5 times a second: 1600)
MAX_POINTS = 4000
#: largest share of a complete revolution's bytes that may have been thrown away
MAX_CORRUPT_FRACTION = 0.2
#: widest angular gap between neighbouring nodes of a complete revolution [rad] (20 deg)
MAX_GAP = math.radians(20.0)

_Q6_TURN = 360 * 64  # angle_q6 units per turn
_MAX_STEP_Q6 = round(math.degrees(MAX_GAP) * 64)
#: nodes in order among themselves but not with the reference before they replace it
_REANCHOR = 3


def _cw_step(a_q6: int, b_q6: int) -> int:
    """Clockwise angle from ``a`` to ``b`` in angle_q6 units, in [0, one turn)."""
    return (b_q6 - a_q6) % _Q6_TURN


@dataclass
class Revolution:
    """The nodes of one revolution (start node first), the bytes thrown away within it,
    and ``stamp``: the caller's time of its start node."""

    nodes: list[MeasurementNode] = field(default_factory=list)
    corrupt_bytes: int = 0
    stamp: float = 0.0
    #: clockwise travel from the start node to the last node [angle_q6], steps wider
    #: than MAX_GAP left out
    travel_q6: int = 0


class RevolutionAssembler:
    """Cuts the node stream at credible start flags (see the module doc).

    :meth:`push` every node from :meth:`~mmexec.drivers.rplidar.codec.NodeParser.feed`
    with the bytes skipped before it and a time; it returns the revolution a credible start
    flag has just closed. A start node is decided when its successor arrives. Order is
    judged against the last node that was in order (a stray node does not move it); after
    :data:`_REANCHOR` nodes in order among themselves but not with it (data lost), they
    become the reference. Nodes before the first credible start belong to no revolution.
    A revolution that grows past :data:`MAX_POINTS` is returned as it is
    (:func:`check_revolution` rejects it) and collection waits for the next start.
    """

    def __init__(self) -> None:
        self._rev: Revolution | None = None
        self._last: int | None = None          # angle_q6 of the last node in order
        self._held: tuple[int, MeasurementNode, float] | None = None
        self._off = 0                          # consecutive nodes out of order with _last ...
        self._off_q6 = 0                       # ... but in order among themselves; the last one
        #: start flags dropped as not credible
        self.bogus_starts = 0

    def push(self, skipped: int, node: MeasurementNode, stamp: float) -> Revolution | None:
        done: Revolution | None = None
        if self._held is not None:
            h_skipped, h_node, h_stamp = self._held
            self._held = None
            if _cw_step(h_node.angle_q6, node.angle_q6) <= _MAX_STEP_Q6:
                done, self._rev = self._rev, Revolution([h_node], h_skipped, h_stamp)
                self._last = h_node.angle_q6
            else:
                self._drop(h_skipped)
        step = 0 if self._last is None else _cw_step(self._last, node.angle_q6)
        in_order = step <= _MAX_STEP_Q6
        rev = self._rev
        if node.start:
            if in_order and (rev is None or rev.travel_q6 + step >= _Q6_TURN - _MAX_STEP_Q6):
                self._held = (skipped, node, stamp)
            else:
                self._drop(skipped)
            return done
        if rev is not None:
            rev.nodes.append(node)
            rev.corrupt_bytes += skipped
            if in_order:
                rev.travel_q6 += step
            if len(rev.nodes) > MAX_POINTS:
                done, self._rev = rev, None
        if in_order:
            self._last, self._off = node.angle_q6, 0
        else:
            self._track_off(node.angle_q6)
        return done

    def _track_off(self, angle_q6: int) -> None:
        """Count nodes out of order with the reference; re-anchor on a consistent run."""
        if self._off and _cw_step(self._off_q6, angle_q6) <= _MAX_STEP_Q6:
            self._off += 1
        else:
            self._off = 1
        self._off_q6 = angle_q6
        if self._off >= _REANCHOR:
            self._last, self._off = angle_q6, 0

    def _drop(self, skipped: int) -> None:
        self.bogus_starts += 1
        if self._rev is not None:
            self._rev.corrupt_bytes += skipped + NODE_SIZE


def drop_out_of_order(nodes: Sequence[MeasurementNode]) -> list[MeasurementNode]:
    """``nodes`` without the isolated ones whose clockwise angle does not lie between
    their neighbours' (angles unwrapped from the first node; the last node is kept)."""
    if len(nodes) < 3:
        return list(nodes)
    q = np.array([n.angle_q6 for n in nodes], dtype=np.int64)
    q = (q - q[0]) % _Q6_TURN
    keep = np.ones(len(nodes), dtype=bool)
    prev, mid, nxt = q[:-2], q[1:-1], q[2:]
    ordered = prev <= nxt
    keep[1:-1] = ~ordered | ((prev <= mid) & (mid <= nxt))
    return [n for n, k in zip(nodes, keep) if k]


def check_revolution(nodes: Sequence[MeasurementNode], corrupt_bytes: int = 0,
                     travel_q6: int | None = None) -> str:
    """Why ``nodes`` (one revolution, start node first, after :func:`drop_out_of_order`)
    is not a complete scan; "" when it is. ``corrupt_bytes``: bytes of the revolution
    thrown away (dropped while resynchronising, and 5 per node dropped out of order);
    ``travel_q6``: :attr:`Revolution.travel_q6`, more than a turn when a start flag was
    lost (then the scan would mix two turns)."""
    if travel_q6 is not None and travel_q6 > _Q6_TURN + _MAX_STEP_Q6:
        return f"{travel_q6 / 64:.0f} deg of travel (a start flag lost)"
    if len(nodes) < MIN_POINTS:
        return f"{len(nodes)} nodes (fewer than {MIN_POINTS})"
    if len(nodes) > MAX_POINTS:
        return f"more than {MAX_POINTS} nodes (start flags lost)"
    total = corrupt_bytes + NODE_SIZE * len(nodes)
    if corrupt_bytes > MAX_CORRUPT_FRACTION * total:
        return f"{corrupt_bytes} of {total} bytes corrupt"
    q = np.sort(np.array([n.angle_q6 for n in nodes], dtype=np.int64) % _Q6_TURN)
    gaps = np.diff(np.append(q, q[0] + _Q6_TURN))
    widest = math.radians(float(gaps.max()) / 64.0)
    if widest > MAX_GAP:
        return f"a {math.degrees(widest):.0f} deg gap without nodes"
    return ""


def resample(nodes: Sequence[MeasurementNode], beams: int) -> tuple[np.ndarray, np.ndarray]:
    """``(ranges [m], intensities [0..1])`` on ``beams`` CCW bins from -pi (module doc)."""
    if beams < 1:
        raise ValueError(f"beams must be >= 1, got {beams}")
    ranges = np.full(beams, np.nan)
    intensities = np.zeros(beams)
    if not nodes:
        return ranges, intensities
    q6 = np.array([n.angle_q6 for n in nodes], dtype=np.float64)
    angle = wrap_angle(-np.radians(q6 / 64.0))
    dist = np.array([n.distance_q2 for n in nodes], dtype=np.float64) / 4000.0
    dist[dist == 0.0] = np.inf
    quality = np.array([n.quality for n in nodes], dtype=np.float64) / 63.0
    order = np.argsort(angle, kind="stable")
    angle, dist, quality = angle[order], dist[order], quality[order]
    inc = 2.0 * math.pi / beams
    spacing = float(np.median(np.diff(np.append(angle, angle[0] + 2.0 * math.pi)))) if len(angle) > 1 else inc
    tol = max(0.5 * inc, 0.75 * spacing)
    centres = -math.pi + inc * np.arange(beams)
    # nearest node to each centre, the circle closed by a copy of each end past the other
    ext = np.concatenate((angle[-1:] - 2.0 * math.pi, angle, angle[:1] + 2.0 * math.pi))
    idx = np.clip(np.searchsorted(ext, centres), 1, len(ext) - 1)
    left_closer = (centres - ext[idx - 1]) <= (ext[idx] - centres)
    nearest = np.where(left_closer, idx - 1, idx)
    err = np.abs(ext[nearest] - centres)
    src = (nearest - 1) % len(angle)
    hit = err <= tol + 1e-12
    ranges[hit] = dist[src[hit]]
    intensities[hit] = np.where(np.isfinite(dist[src[hit]]), quality[src[hit]], 0.0)
    return ranges, intensities
