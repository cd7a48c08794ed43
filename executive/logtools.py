"""Reading event logs back: ``mmexec log summary`` and ``mmexec log replay``.

Both work on the records of :func:`mmexec.executive.eventlog.read_log` and return text,
so they are testable without a terminal. The record types are documented in
:mod:`mmexec.executive.eventlog`.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

__all__ = ["Frame", "render_frame", "replay_frames", "summary"]

#: py_trees' status symbols.
SYMBOLS = {"SUCCESS": "✓", "FAILURE": "✕", "RUNNING": "*", "INVALID": "-"}


def _fmt_request(req: Any) -> str:
    if isinstance(req, dict) and req:
        return ", ".join(f"{k}={v}" for k, v in req.items())
    return "-"


def _dur(x: Any) -> str:
    return f"{x:.1f} s" if isinstance(x, (int, float)) else "?"


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
            idx = int(r.get("index", len(order) + 1))
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
    n_req = start.get("requests", total) if start else total
    lines.append("")
    reasons: Counter[str] = Counter()
    outcomes: Counter[str] = Counter()
    durations: list[float] = []
    for idx in order:
        info = per_req[idx]
        end_rec = info["end"]
        req = _fmt_request(info["start"].get("request"))
        if end_rec is None:
            lines.append(f"request {idx}/{n_req} ({req}): unfinished (log ends mid-request)")
            outcomes["unfinished"] += 1
            continue
        outcome = end_rec.get("outcome", "?")
        outcomes[outcome] += 1
        if isinstance(end_rec.get("duration"), (int, float)):
            durations.append(float(end_rec["duration"]))
        head = f"request {idx}/{n_req} ({req}): {outcome} after {_dur(end_rec.get('duration'))}"
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
            reason = end_rec.get("reason") or "(no reason recorded)"
            node = end_rec.get("failure_node")
            lines.append(f"    reason: {reason}" + (f" [{node}]" if node else ""))
            reasons[reason] += 1
    for r in reloads:
        state = "ok" if r.get("ok") else "rejected: " + "; ".join(r.get("problems", []))
        lines.append(f"mission reload at {_dur(r.get('t'))}: {state}")

    lines.append("")
    ok = outcomes.get("success", 0)
    parts = ", ".join(f"{v} {k}" for k, v in sorted(outcomes.items()))
    lines.append(f"requests: {total} served of {n_req}, {ok} succeeded ({parts or 'none'})")
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
    """The tree's state after one clock instant of one request."""

    index: int
    of: int
    t: float
    nodes: list[str]
    status: dict[str, str]
    changed: set[str] = field(default_factory=set)
    events: list[str] = field(default_factory=list)


def replay_frames(records: Sequence[dict[str, Any]], request: int | None = None) -> Iterator[Frame]:
    """Rebuild the tree's states from ``request_start`` (node list) and ``node_status``
    records: one :class:`Frame` per clock time at which something changed. ``request``
    keeps only that request (1-based)."""
    frame: Frame | None = None
    nodes: list[str] = []
    status: dict[str, str] = {}
    idx = of = 0
    for r in records:
        ev = r.get("event")
        if ev == "request_start":
            if frame is not None:
                yield frame
                frame = None
            idx, of = int(r.get("index", 0)), int(r.get("of", 0))
            nodes = list(r.get("nodes") or [])
            status = {p: "INVALID" for p in nodes}
            continue
        if request is not None and idx != request:
            continue
        if ev == "node_status":
            t = float(r.get("t", 0.0))
            if frame is not None and abs(frame.t - t) > 1e-9:
                yield frame
                frame = None
            path = str(r.get("path"))
            if path not in status:
                nodes.append(path)
            status[path] = str(r.get("new"))
            if frame is None:
                frame = Frame(idx, of, t, list(nodes), {}, set(), [])
            frame.nodes = list(nodes)
            frame.status = dict(status)
            frame.changed.add(path)
        elif ev in ("skill_failure", "recovery_attempt", "recovery_give_up", "recovery_failed", "halt",
                    "skill_cancel", "report", "request_end") and frame is not None:
            detail = r.get("reason") or r.get("message") or r.get("outcome") or ""
            frame.events.append(f"{ev} {r.get('node', '')} {detail}".strip())
    if frame is not None:
        yield frame


def render_frame(frame: Frame) -> str:
    """Text of one frame: a header and the tree, indented by path depth, with py_trees'
    status symbols; nodes that changed at this instant are marked with ``<<``."""
    lines = [f"── request {frame.index}/{frame.of}  t = {frame.t:.2f} s ──"]
    base = min((p.count("/") for p in frame.nodes), default=0)
    for p in frame.nodes:
        st = frame.status.get(p, "INVALID")
        name = p.rsplit("/", 1)[-1]
        mark = "  <<" if p in frame.changed else ""
        lines.append(f"{'    ' * (p.count('/') - base)}{SYMBOLS.get(st, '?')} {name} [{st}]{mark}")
    for e in frame.events:
        lines.append(f"  ! {e}")
    return "\n".join(lines)
