"""Navigation among people and unmapped obstacles, as a campaign measures it (issue 12).

Two sources per trial:

* the ground-truth sidecar (``DIR/truth/SEED.jsonl``, :mod:`mmexec.sim.truth`; never
  read by skills): every contact of the robot (base or arm) and with what, the true gap
  from the footprint to each person and the true clearance of the footprint at every
  control tick. :func:`truth_measures` counts them: contacts with a person (the target
  is none in any trial), the smallest true gap to a person, the smallest true clearance,
  and the ticks where the true barrier held (``h >= 0``: the footprint circle clear of
  every static part and every person, i.e. clearance >= 0 and every gap >= 0);
* the trial's event log: the safety filter's own smallest barrier value ``h`` [m^2] over
  the circles it tracked, logged in each ``nav_tick`` record (skills/navigation/
  local_drive.py, following the DWA and docking) exactly as the filter enforced it: the
  paper's ``h = |p - c|^2 - r_u^2`` at the axle centre, ``r_u`` the circle's covering
  radius + the footprint radius + ``nav.margin`` (skills/navigation/cbf.py), so ``h >= 0``
  is "the footprint at least the margin clear of the circle as the lidar sees it".
  :func:`log_measures` counts the logged ticks and those with ``h < 0``, and tells apart
  the runs of ``h < 0`` (consecutive logged ticks) that began with *a person walking into
  the standing base* (the circle with the smallest ``h`` a tracked person closing at more
  than :data:`CLOSING` while the base's measured speed was at most :data:`STANDING`:
  nothing the base could have done, bar moving sideways, which a unicycle cannot), those
  that began with *the circle jumping* (``h`` fell from the tick before by more than the
  base's and the circle's logged speeds can explain, ``2 |p - c| (|v| + closing) dt``,
  plus :data:`JUMP_SLACK`: a circle first seen inside the zone, or one that grew or moved
  between two scans as more of a body came into view; the perception, not the motion),
  and the others (the base's own doing).

:func:`summarize_nav` folds the trials' measures into the campaign summary
(``summary.json`` key ``nav_truth``) and :func:`nav_report_lines` into report.md.
Distances in m, ``h`` in m^2.
"""

from __future__ import annotations

import json
import math
import statistics
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

__all__ = ["CLOSING", "JUMP_SLACK", "STANDING", "log_measures", "nav_report_lines", "summarize_nav", "truth_measures"]

#: [m/s] a person closing on the base faster than this is walking into it
CLOSING = 0.05
#: [m/s] a base whose measured speed is at most this is standing
STANDING = 0.05
#: [m^2] a fall of h beyond what the logged speeds explain by more than this is a jump
JUMP_SLACK = 0.01


def truth_measures(path: Path) -> dict[str, Any]:
    """The navigation measures of one trial's ground-truth sidecar ``path`` ({} when it
    has no tick records). Keys: ``truth_ticks``, ``truth_ticks_clear`` (footprint clear of
    everything: the true ``h >= 0``), ``min_clearance`` [m], ``min_gap_person`` [m]
    (None without people), ``contacts``, ``person_contacts``, ``contact_bodies``
    ({body: count}); ``truth_error`` when the file cannot be read."""
    people: set[str] = set()
    ticks = clear = contacts = person_contacts = 0
    bodies: dict[str, int] = {}
    min_clear, min_gap = math.inf, math.inf
    try:
        records = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    except (OSError, ValueError):
        return {"truth_error": f"unreadable ground truth {path}"}
    for rec in records:
        event = rec.get("event")
        if event == "truth":
            ticks += 1
            c = rec.get("clearance", math.inf)
            g = min(rec.get("gaps", ()), default=math.inf)
            min_clear, min_gap = min(min_clear, c), min(min_gap, g)
            clear += c >= 0.0 and g >= 0.0
        elif event == "contact":
            contacts += 1
            body = str(rec.get("body", ""))
            bodies[body] = bodies.get(body, 0) + 1
            person_contacts += body in people
        elif event == "truth_start":
            people = {str(p["name"]) for p in rec.get("people", ())}
    if not ticks:
        return {}
    return {"truth_ticks": ticks, "truth_ticks_clear": clear, "min_clearance": min_clear,
            "min_gap_person": min_gap if people and math.isfinite(min_gap) else None,
            "contacts": contacts, "person_contacts": person_contacts, "contact_bodies": bodies}


def _person_walked_in(rec: Mapping[str, Any]) -> bool:
    """The tick's smallest barrier belongs to a tracked person closing on a standing base."""
    closing, v = rec.get("h_closing"), rec.get("v_meas")
    return (bool(rec.get("h_person")) and isinstance(closing, (int, float)) and closing > CLOSING
            and isinstance(v, (int, float)) and abs(v) <= STANDING)


def _jumped(prev: Mapping[str, Any] | None, rec: Mapping[str, Any]) -> bool:
    """``h`` fell from ``prev`` to ``rec`` by more than the logged speeds explain."""
    if prev is None or not all(isinstance(rec.get(k), (int, float)) for k in ("h_dist", "v_meas", "t")) \
            or not isinstance(prev.get("t"), (int, float)):
        return False
    dt = max(float(rec["t"]) - float(prev["t"]), 0.0)
    closing = max(0.0, float(rec.get("h_closing") or 0.0))
    explained = 2.0 * float(rec["h_dist"]) * (abs(float(rec["v_meas"])) + closing) * dt
    return float(prev["h"]) - float(rec["h"]) > explained + JUMP_SLACK


def log_measures(records: Iterable[Mapping[str, Any]]) -> dict[str, Any]:
    """The safety filter's logged barrier values in a trial's event log: ``nav_ticks``
    (ticks with a barrier value), ``nav_ticks_h_negative``, of those
    ``nav_ticks_h_negative_person_in`` (in runs of ``h < 0`` that began with a person
    walking into the standing base; module docstring) and ``nav_runs_h_negative`` /
    ``nav_runs_person_in`` (the runs), ``nav_ticks_h_negative_jump`` / ``nav_runs_jump``
    (runs that began with the circle jumping), ``nav_ticks_escaped`` (commands from the
    filter's escape solve) and ``nav_min_h`` [m^2]; {} when no tick logged one (the plain
    drive, or nothing tracked)."""
    ticks = [r for r in records if r.get("event") == "nav_tick" and isinstance(r.get("h"), (int, float))
             and math.isfinite(r["h"])]
    if not ticks:
        return {}
    negative = person_in = jump = runs = runs_in = runs_jump = 0
    in_run = run_person = run_jump = False
    prev: Mapping[str, Any] | None = None
    for r in ticks:
        if r["h"] < 0.0:
            if not in_run:
                in_run, run_person = True, _person_walked_in(r)
                run_jump = not run_person and _jumped(prev, r)
                runs += 1
                runs_in += run_person
                runs_jump += run_jump
            negative += 1
            person_in += run_person
            jump += run_jump
        else:
            in_run = False
        prev = r
    return {"nav_ticks": len(ticks), "nav_ticks_h_negative": negative, "nav_ticks_h_negative_person_in": person_in,
            "nav_runs_h_negative": runs, "nav_runs_person_in": runs_in, "nav_ticks_h_negative_jump": jump,
            "nav_runs_jump": runs_jump,
            "nav_ticks_escaped": sum(bool(r.get("escaped")) for r in ticks), "nav_min_h": min(r["h"] for r in ticks)}


def _spread(values: Sequence[float]) -> dict[str, float | None]:
    return {"min": min(values) if values else None, "median": statistics.median(values) if values else None}


def summarize_nav(truths: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """The campaign's navigation measures over its trials' ``truth`` dicts (those with
    :func:`truth_measures` / :func:`log_measures` keys); {} when none has any."""
    rows = [t for t in truths if "truth_ticks" in t]
    logged = [t for t in truths if "nav_ticks" in t]
    if not rows and not logged:
        return {}
    gaps = [t["min_gap_person"] for t in rows if t.get("min_gap_person") is not None]
    ticks = sum(t["truth_ticks"] for t in rows)
    nav_ticks = sum(t["nav_ticks"] for t in logged)
    bodies: dict[str, int] = {}
    for t in rows:
        for b, n in t["contact_bodies"].items():
            bodies[b] = bodies.get(b, 0) + n
    return {
        "trials": len(rows),
        "trials_with_people": len(gaps),
        "trials_with_person_contact": sum(t["person_contacts"] > 0 for t in rows),
        "person_contacts": sum(t["person_contacts"] for t in rows),
        "trials_with_contact": sum(t["contacts"] > 0 for t in rows),
        "contact_bodies": dict(sorted(bodies.items(), key=lambda kv: -kv[1])),
        "min_gap_person": _spread(gaps),
        "min_clearance": _spread([t["min_clearance"] for t in rows]),
        "truth_ticks": ticks,
        "truth_ticks_clear_share": sum(t["truth_ticks_clear"] for t in rows) / ticks if ticks else None,
        "trials_all_ticks_clear": sum(t["truth_ticks_clear"] == t["truth_ticks"] for t in rows),
        "nav_ticks": nav_ticks,
        "nav_ticks_h_nonnegative_share": 1.0 - sum(t["nav_ticks_h_negative"] for t in logged) / nav_ticks
        if nav_ticks else None,
        "nav_ticks_h_negative": sum(t["nav_ticks_h_negative"] for t in logged),
        "nav_ticks_h_negative_person_in": sum(t.get("nav_ticks_h_negative_person_in", 0) for t in logged),
        "nav_runs_h_negative": sum(t.get("nav_runs_h_negative", 0) for t in logged),
        "nav_runs_person_in": sum(t.get("nav_runs_person_in", 0) for t in logged),
        "nav_ticks_h_negative_jump": sum(t.get("nav_ticks_h_negative_jump", 0) for t in logged),
        "nav_runs_jump": sum(t.get("nav_runs_jump", 0) for t in logged),
        "trials_h_negative_other": sum(t["nav_ticks_h_negative"] > t.get("nav_ticks_h_negative_person_in", 0)
                                       + t.get("nav_ticks_h_negative_jump", 0) for t in logged),
        "nav_ticks_escaped": sum(t.get("nav_ticks_escaped", 0) for t in logged),
        "nav_min_h": min((t["nav_min_h"] for t in logged), default=None),
    }


def _m(x: float | None, digits: int = 3) -> str:
    return "-" if x is None else f"{x:.{digits}f}"


def nav_report_lines(nav: Mapping[str, Any]) -> list[str]:
    """report.md's "Navigation (ground truth)" section for :func:`summarize_nav`'s dict."""
    if not nav:
        return []
    g, c = nav["min_gap_person"], nav["min_clearance"]
    share = nav["truth_ticks_clear_share"]
    hshare = nav["nav_ticks_h_nonnegative_share"]
    what = ", ".join(f"{b} x{n}" for b, n in nav["contact_bodies"].items()) or "none"
    other_ticks = (nav.get("nav_ticks_h_negative", 0) - nav.get("nav_ticks_h_negative_person_in", 0)
                   - nav.get("nav_ticks_h_negative_jump", 0))
    other_runs = nav.get("nav_runs_h_negative", 0) - nav.get("nav_runs_person_in", 0) - nav.get("nav_runs_jump", 0)
    return [
        "## Navigation (ground truth)", "",
        "| measure | value |", "|---|---|",
        (f"| trials with a contact with a person (target 0) | {nav['trials_with_person_contact']}/{nav['trials']} "
        f"({nav['person_contacts']} contacts) |"),
        (f"| smallest true gap footprint-person, min / median over trials | {_m(g['min'])} / {_m(g['median'])} m "
        f"({nav['trials_with_people']} trials with people) |"),
        f"| smallest true clearance of the footprint, min / median over trials | {_m(c['min'])} / {_m(c['median'])} m |",
        (f"| ticks with the true h >= 0 (footprint clear of everything) | "
        f"{'-' if share is None else f'{100 * share:.3f} %'} of {nav['truth_ticks']}; "
        f"{nav['trials_all_ticks_clear']}/{nav['trials']} trials at every tick |"),
        (f"| logged ticks with the filter's h >= 0 (the enforced barrier: footprint >= margin from each circle) | "
        f"{'-' if hshare is None else f'{100 * hshare:.3f} %'} of {nav['nav_ticks']}; smallest h "
        f"{_m(nav['nav_min_h'], 4)} m^2 |"),
        (f"| logged ticks with h < 0: a person walking into the standing base / the circle jumping "
        f"inside the zone between two scans / other | "
        f"{nav.get('nav_ticks_h_negative_person_in', 0)} ({nav.get('nav_runs_person_in', 0)} runs) / "
        f"{nav.get('nav_ticks_h_negative_jump', 0)} ({nav.get('nav_runs_jump', 0)} runs) / "
        f"{other_ticks} ({other_runs} runs, {nav.get('trials_h_negative_other', 0)} trials) |"),
        f"| logged commands from the filter's escape (a bounded reverse) | {nav.get('nav_ticks_escaped', 0)} |",
        f"| trials with any contact (base or arm) | {nav['trials_with_contact']}/{nav['trials']}: {what} |",
        "",
    ]
