"""What a trial is (:class:`TrialSpec`: the ``mmexec run`` command, its log, its limits)
and what it did (:class:`TrialResult`, read from its event log and exit status by
:func:`parse_trial_log`)."""

from __future__ import annotations

import dataclasses
import json
import os
import shlex
import signal
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mmexec.executive.campaign.navtruth import log_measures, truth_measures

__all__ = ["TrialResult", "TrialSpec", "parse_trial_log", "read_truth"]

#: [mm] a press counts as on the button within this distance of its centre
PRESS_TOLERANCE_MM = 5.0


@dataclass(frozen=True)
class TrialSpec:
    """One trial to run: ``argv`` of ``mmexec`` (starting with ``run``), the event log it
    writes, where to run it (``cwd``), an optional wall-time limit [s] and where its
    console output goes."""

    index: int
    seed: int
    argv: tuple[str, ...]
    log_path: str
    out_path: str
    cwd: str
    wall_limit: float | None = None

    @property
    def command(self) -> str:
        """The shell command reproducing this trial alone (without the campaign's own
        output files, ``--log`` and ``--mcap``, and their ``--overwrite``)."""
        argv = list(self.argv)
        for option in ("--log", "--mcap"):
            if option in argv:
                i = argv.index(option)
                del argv[i:i + 2]
        if "--overwrite" in argv:
            argv.remove("--overwrite")
        return shlex.join(["mmexec", *argv])


@dataclass
class TrialResult:
    """What one trial did. ``outcome``: ``success`` (every request succeeded),
    ``failure`` (a request failed or timed out), ``error`` (the trial process crashed,
    was killed, or a request raised), or ``interrupted`` (Ctrl-C; not recorded, re-run
    on resume). ``clock`` is the sum of its requests' durations [clock s], ``wall`` the
    trial process's wall time [s]."""

    index: int
    seed: int
    outcome: str
    clock: float
    wall: float
    recoveries: int
    reason: str
    failure_kind: str = ""
    failure_node: str = ""
    exit_code: int | None = None
    requests: list[dict[str, Any]] = field(default_factory=list)
    command: str = ""
    log: str = ""
    host: str = ""
    #: what the trial's ground truth says (:func:`read_truth`; empty without one)
    truth: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> TrialResult:
        names = {f.name for f in dataclasses.fields(cls)}
        return cls(**{k: v for k, v in data.items() if k in names})


def _signal_name(rc: int) -> str:
    try:
        return signal.Signals(-rc).name
    except ValueError:
        return f"signal {-rc}"


def read_truth(spec: TrialSpec) -> dict[str, Any]:
    """The measures a campaign counts from the trial's ground-truth sidecar
    (``DIR/truth/SEED.jsonl``, written by a backend with a ``truth_key``), or {} without
    one. Control panels (sim/panel.py): ``panel_presses`` (each switched press's offset
    from its button's centre [mm], None when no robot link touched it at the deepest
    travel), ``panel_lights`` / ``panel_lights_on`` (lights at the end), ``presses_within``
    (switched presses within :data:`PRESS_TOLERANCE_MM`)."""
    path = Path(spec.log_path).parent.parent / "truth" / f"{spec.seed}.jsonl"
    if not path.is_file():
        return {}
    presses: list[float | None] = []
    lights: dict[str, bool] = {}
    try:
        for line in path.read_text().splitlines():
            if '"panel_' not in line:
                continue
            rec = json.loads(line)
            if rec.get("event") == "panel_press" and rec.get("switched"):
                presses.append(rec.get("offset_mm"))
            elif rec.get("event") == "panel_end":
                lights.update(rec.get("lights", {}))
    except (OSError, ValueError):
        return {"truth_error": f"unreadable ground truth {path}"}
    nav = truth_measures(path)  # contacts, gaps to people, clearance (navtruth.py)
    if not presses and not lights:
        return nav
    return {**nav, "panel_presses": presses, "panel_lights": len(lights), "panel_lights_on": sum(map(bool, lights.values())),
            "presses_within": sum(1 for p in presses if p is not None and p <= PRESS_TOLERANCE_MM)}


def parse_trial_log(spec: TrialSpec, *, exit_code: int | None, wall: float, note: str = "") -> TrialResult:
    """Turn a trial's event log (and how its process ended) into a :class:`TrialResult`.
    ``note`` is the reason to record if the process did not finish normally."""
    from mmexec.executive.eventlog import LogFormatError, read_log

    records: list[dict[str, Any]] = []
    problem = ""
    try:
        records = read_log(spec.log_path)
    except FileNotFoundError:
        problem = "no event log written"
    except LogFormatError as e:
        problem = f"unreadable event log: {e}"
    requests = [r for r in records if r.get("event") == "request_end"]
    run_end = next((r for r in records if r.get("event") == "run_end"), None)
    rows = [{"request": r.get("request", {}), "outcome": r.get("outcome", ""), "duration": float(r.get("duration", 0.0)),
             "recoveries": int(r.get("recoveries", 0)), "reason": r.get("reason", ""),
             "failure_kind": r.get("failure_kind", ""), "failure_node": r.get("failure_node", "")} for r in requests]
    clock = sum(r["duration"] for r in rows)
    recoveries = sum(r["recoveries"] for r in rows)
    common = {"index": spec.index, "seed": spec.seed, "clock": clock, "wall": wall, "recoveries": recoveries,
              "exit_code": exit_code, "requests": rows, "command": spec.command, "log": spec.log_path,
              "host": os.uname().nodename, "truth": {**read_truth(spec), **log_measures(records)}}
    if run_end is not None and run_end.get("outcome") == "interrupted":
        return TrialResult(outcome="interrupted", reason="interrupted (Ctrl-C)", **common)
    crashed = run_end is None or run_end.get("outcome") == "error" or exit_code not in (0, 1)
    if crashed:
        if note:
            reason = note
        elif exit_code is not None and exit_code < 0:
            reason = f"trial process killed by {_signal_name(exit_code)}"
        elif run_end is not None and run_end.get("error"):
            reason = f"run ended with an error: {run_end.get('error')}"
        else:
            reason = f"trial process exited with code {exit_code}"
            if run_end is None:
                reason += " before its run_end record"
        if problem:
            reason += f" ({problem})"
        return TrialResult(outcome="error", reason=reason, **common)
    bad = next((r for r in rows if r["outcome"] != "success"), None)
    if bad is None and len(rows) == int(run_end.get("requests", len(rows))):
        return TrialResult(outcome="success", reason="", **common)
    if bad is None:
        return TrialResult(outcome="error", reason="not every request was served", **common)
    reason = bad["reason"] or bad["outcome"]
    outcome = "error" if bad["outcome"] == "error" else "failure"
    return TrialResult(outcome=outcome, reason=reason, failure_kind=bad["failure_kind"],
                       failure_node=bad["failure_node"], **common)
