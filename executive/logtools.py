"""Reading event logs back: ``mmexec log summary`` and ``mmexec log replay``.

Both work on the records of :func:`mmexec.executive.eventlog.read_log` and return text,
so they are testable without a terminal. The record types are documented in
:mod:`mmexec.executive.eventlog`.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

__all__ = ["FRAME_EVENTS", "Frame", "NoSuchRequest", "render_frame", "replay_frames", "request_count", "summary"]

#: py_trees' status symbols.
SYMBOLS = {"SUCCESS": "✓", "FAILURE": "✕", "RUNNING": "*", "INVALID": "-"}


def _fmt_request(req: Any) -> str:
    if isinstance(req, dict) and req:
        return ", ".join(f"{k}={v}" for k, v in req.items())
    return "-"


def _finite(value: Any) -> float | None:
    """``value`` as a float when it is a finite JSON number (not a bool), else None: a log
    written by hand or cut mid-record may carry anything."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return None
    return float(value)


def _int(value: Any, default: int) -> int:
    """``value`` as an int when it is an integral JSON number, else ``default``."""
    x = _finite(value)
    return int(x) if x is not None and x.is_integer() else default


def _time(value: Any, default: float) -> float:
    """``value`` as clock seconds [s] when it is a finite JSON number, else ``default``."""
    x = _finite(value)
    return default if x is None else x


def _dur(value: Any) -> str:
    x = _finite(value)
    return "?" if x is None else f"{x:.1f} s"


def summary(records: Sequence[dict[str, Any]]) -> str:
    """A readable summary: run identity, one block per request (outcome, duration,
    recoveries with their reasons, skill failures), totals and failure reasons."""
    lines: list[str] = []
    start = next((r for r in records if r.get("event") == "run_start"), None)
    end = next((r for r in reversed(records) if r.get("event") == "run_end"), None)
    if start is not None:
        lines.append(f"mission: {start.get('mission')} (sha256 {str(start.get('mission_sha256', ''))[:12]})")
        lines.append(f"config:  {start.get('config')} (sha256 {str(start.get('config_sha256', ''))[:12]}), "
                     f"backend {start.get('backend')}, seed {start.get('seed')}, {start.get('rate_hz')} Hz")
        if start.get("started"):
            lines.append(f"started: {start['started']}")
    else:
        lines.append("no run_start record (not an mmexec event log, or truncated at the start)")

    current: dict[str, Any] | None = None
    per_req: dict[int, dict[str, Any]] = {}
    order: list[int] = []
    reloads: list[dict[str, Any]] = []
    for r in records:
        ev = r.get("event")
        if ev == "request_start":
            idx = _int(r.get("index"), len(order) + 1)
            current = per_req[idx] = {"start": r, "recoveries": [], "failures": [], "end": None}
            order.append(idx)
        elif ev == "mission_reload":
            reloads.append(r)
        elif current is not None:
            if ev == "recovery_attempt":
                current["recoveries"].append(r)
            elif ev == "skill_failure":
                current["failures"].append(r)
            elif ev == "request_end":
                current["end"] = r
                current = None

    total = len(order)
    # a served run (``mmexec serve``) has no fixed number of requests: its run_start says 0
    n_req = _int(start.get("requests"), total) if start else total
    lines.append("")
    reasons: Counter[str] = Counter()
    outcomes: Counter[str] = Counter()
    durations: list[float] = []
    for idx in order:
        info = per_req[idx]
        end_rec = info["end"]
        req = _fmt_request(info["start"].get("request"))
        if end_rec is None:
            lines.append(f"request {_of(idx, n_req)} ({req}): unfinished (log ends mid-request)")
            outcomes["unfinished"] += 1
            continue
        outcome = str(end_rec.get("outcome", "?"))
        outcomes[outcome] += 1
        duration = _finite(end_rec.get("duration"))
        if duration is not None:
            durations.append(duration)
        head = f"request {_of(idx, n_req)} ({req}): {outcome} after {_dur(end_rec.get('duration'))}"
        n_rec = len(info["recoveries"])
        head += f", {n_rec} recover{'y' if n_rec == 1 else 'ies'}" if n_rec else ""
        lines.append(head)
        for rec in info["recoveries"]:
            lines.append(f"    recovery {rec.get('attempt')} at {_dur(rec.get('t'))} in {rec.get('node')}: "
                         f"{rec.get('reason', '')}")
        for f in info["failures"]:
            lines.append(f"    skill {f.get('skill')} failed ({f.get('kind')}) at {_dur(f.get('t'))} "
                         f"in {f.get('node')}: {f.get('reason')}")
        if outcome != "success":
            reason = str(end_rec.get("reason") or "(no reason recorded)")
            node = end_rec.get("failure_node")
            lines.append(f"    reason: {reason}" + (f" [{node}]" if node else ""))
            reasons[reason] += 1
    for r in reloads:
        problems = r.get("problems")
        state = "ok" if r.get("ok") else "rejected: " + "; ".join(map(str, problems if isinstance(problems, list) else []))
        lines.append(f"mission reload at {_dur(r.get('t'))}: {state}")

    lines.append("")
    ok = outcomes.get("success", 0)
    parts = ", ".join(f"{v} {k}" for k, v in sorted(outcomes.items()))
    lines.append(f"requests: {total} served{f' of {n_req}' if n_req else ''}, {ok} succeeded ({parts or 'none'})")
    if durations:
        lines.append(f"duration: total {sum(durations):.1f} s, mean {sum(durations) / len(durations):.1f} s, "
                     f"max {max(durations):.1f} s (clock)")
    if reasons:
        lines.append("failure reasons:")
        for reason, count in reasons.most_common():
            lines.append(f"  {count} x {reason}")
    if end is not None:
        lines.append(f"run: {end.get('outcome')} (exit {end.get('exit_code')})"
                     + (f": {end['error']}" if end.get("error") else ""))
    else:
        lines.append("run: no run_end record (the process was killed or is still running)")
    return "\n".join(lines)


@dataclass
class Frame:
    """The tree's state after one clock instant of one request: ``t`` [clock s], the node
    paths in tree order, each node's status, the paths that changed at ``t`` and the
    events recorded at ``t``."""

    index: int
    of: int
    t: float
    nodes: list[str]
    status: dict[str, str]
    changed: set[str] = field(default_factory=set)
    events: list[str] = field(default_factory=list)


#: Records shown as the events of a frame (under the frame of their own ``t``).
FRAME_EVENTS = frozenset({"skill_failure", "skill_cancel", "recovery_attempt", "recovery_give_up",
                          "recovery_failed", "halt", "halt_abandoned", "report", "request_end"})

#: Two clock times [s] closer than this are the same instant (one tick).
SAME_INSTANT = 1e-9


class NoSuchRequest(LookupError):
    """``replay_frames(request=N)`` for an N the log does not hold; the message is one
    line (``no request 5: the log has 2 requests``)."""


def request_count(records: Sequence[dict[str, Any]]) -> int:
    """How many requests the log holds (its ``request_start`` records)."""
    return sum(1 for r in records if r.get("event") == "request_start")


def replay_frames(records: Sequence[dict[str, Any]], request: int | None = None) -> Iterator[Frame]:
    """Rebuild the tree's states from ``request_start`` (node list), ``node_status`` and
    event records: one :class:`Frame` per clock time at which a node changed or an event
    of :data:`FRAME_EVENTS` was recorded; every change and event is shown under the frame
    of its own ``t`` (a record without a usable ``t`` belongs to the instant before it).
    ``request`` keeps only that request (1-based); a number the log does not hold raises
    :class:`NoSuchRequest` at once (before iteration)."""
    if request is not None:
        n = request_count(records)
        if not 1 <= request <= n:
            held = f"{n} request{'' if n == 1 else 's'}" if n else "no requests"
            raise NoSuchRequest(f"no request {request}: the log has {held}")
    return _frames(records, request)


def _of(index: int, total: int | None) -> str:
    """``"3/10"`` for request 3 of a run with 10; ``"3"`` when the run had no fixed total
    (a served run's requests arrive one by one: its records say 0 or None)."""
    return f"{index}/{total}" if total else str(index)


def _frames(records: Sequence[dict[str, Any]], request: int | None) -> Iterator[Frame]:
    frame: Frame | None = None
    nodes: list[str] = []
    status: dict[str, str] = {}
    idx = of = 0
    now = 0.0
    for r in records:
        ev = r.get("event")
        if ev == "request_start":
            if frame is not None:
                yield frame
                frame = None
            idx, of = _int(r.get("index"), idx + 1), _int(r.get("of"), 0)
            listed = r.get("nodes")
            nodes = [str(p) for p in listed] if isinstance(listed, list) else []
            status = dict.fromkeys(nodes, "INVALID")
            now = _time(r.get("t"), now)
            continue
        if (request is not None and idx != request) or (ev != "node_status" and ev not in FRAME_EVENTS):
            continue
        t = _time(r.get("t"), now)
        if frame is not None and abs(frame.t - t) > SAME_INSTANT:
            yield frame
            frame = None
        now = t
        if frame is None:
            frame = Frame(idx, of, t, list(nodes), dict(status))
        if ev == "node_status":
            path = str(r.get("path"))
            if path not in status:
                nodes.append(path)
                frame.nodes = list(nodes)
            status[path] = frame.status[path] = str(r.get("new"))
            frame.changed.add(path)
        else:
            detail = r.get("reason") or r.get("message") or r.get("outcome") or ""
            frame.events.append(f"{ev} {r.get('node', '')} {detail}".strip())
    if frame is not None:
        yield frame


def render_frame(frame: Frame) -> str:
    """Text of one frame: a header and the tree, indented by path depth, with py_trees'
    status symbols; nodes that changed at this instant are marked with ``<<``."""
    lines = [f"── request {_of(frame.index, frame.of)}  t = {frame.t:.2f} s ──"]
    base = min((p.count("/") for p in frame.nodes), default=0)
    for p in frame.nodes:
        st = frame.status.get(p, "INVALID")
        name = p.rsplit("/", 1)[-1]
        mark = "  <<" if p in frame.changed else ""
        lines.append(f"{'    ' * (p.count('/') - base)}{SYMBOLS.get(st, '?')} {name} [{st}]{mark}")
    for e in frame.events:
        lines.append(f"  ! {e}")
    return "\n".join(lines)
