"""The campaign's navigation measures (executive/campaign/navtruth.py): a ground-truth
sidecar and an event log written by hand, counted, summarised and reported."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from mmexec.executive.campaign.navtruth import (
    log_measures,
    nav_report_lines,
    summarize_nav,
    truth_measures,
)


def _sidecar(path: Path, ticks: list[tuple[float, list[float]]], contacts: list[str]) -> Path:
    """A sidecar with two people, ``ticks`` of (clearance, gaps) and contacts with ``contacts``."""
    recs = [{"event": "truth_start", "world": "lab", "seed": 1, "robot_radius": 0.178, "obstacles": [],
             "people": [{"name": "crowd_1", "radius": 0.2, "waypoints": []},
                        {"name": "crowd_2", "radius": 0.2, "waypoints": []}]}]
    for k, (clear, gaps) in enumerate(ticks):
        recs.append({"event": "truth", "t": 0.05 * (k + 1), "pose": [1.0, 1.0, 0.0], "clearance": clear,
                     "nearest": "wall", "people": [[2.0, 2.0], [3.0, 3.0]], "gaps": gaps})
    recs += [{"event": "contact", "t": 1.0, "part": "arm", "body": b, "pose": [1.0, 1.0, 0.0]} for b in contacts]
    recs.append({"event": "truth_end", "ticks": len(ticks)})
    path.write_text("".join(json.dumps(r, separators=(",", ":")) + "\n" for r in recs))
    return path


def test_truth_measures_count_contacts_gaps_and_clear_ticks(tmp_path):
    m = truth_measures(_sidecar(tmp_path / "1.jsonl", [(0.3, [0.5, 0.9]), (0.1, [-0.02, 0.8]), (-0.01, [0.4, 0.4]),
                                                        (0.2, [0.3, 0.6])], ["crate", "crowd_2", "crate"]))
    assert m["truth_ticks"] == 4 and m["truth_ticks_clear"] == 2
    assert m["min_clearance"] == pytest.approx(-0.01) and m["min_gap_person"] == pytest.approx(-0.02)
    assert m["contacts"] == 3 and m["person_contacts"] == 1 and m["contact_bodies"] == {"crate": 2, "crowd_2": 1}


def test_a_sidecar_without_people_or_ticks(tmp_path):
    path = tmp_path / "2.jsonl"
    path.write_text(json.dumps({"event": "truth_start", "people": []}) + "\n"
                    + json.dumps({"event": "truth", "clearance": 0.2, "pose": [0, 0, 0]}) + "\n")
    m = truth_measures(path)
    assert m["min_gap_person"] is None and m["truth_ticks_clear"] == 1 and m["person_contacts"] == 0
    path.write_text(json.dumps({"event": "truth_start", "people": []}) + "\n")
    assert truth_measures(path) == {}


def test_log_measures_read_the_filters_barrier_values():
    recs = [{"event": "nav_tick", "h": 0.3}, {"event": "nav_tick", "h": None}, {"event": "nav_tick", "h": -0.05},
            {"event": "base_status"}, {"event": "nav_tick", "h": 1.2}]
    assert log_measures(recs) == {"nav_ticks": 3, "nav_ticks_h_negative": 1, "nav_ticks_h_negative_person_in": 0,
                                  "nav_runs_h_negative": 1, "nav_runs_person_in": 0, "nav_ticks_h_negative_jump": 0,
                                  "nav_runs_jump": 0, "nav_ticks_escaped": 0, "nav_min_h": -0.05}
    assert log_measures([{"event": "nav_tick", "h": None}]) == {}


def _tick(h, person=False, closing=0.0, v=0.0, escaped=False):
    return {"event": "nav_tick", "h": h, "h_person": person, "h_closing": closing, "v_meas": v, "escaped": escaped}


def test_runs_of_negative_h_begun_by_a_person_walking_into_the_standing_base():
    """A run of h < 0 counts as a person's doing only when it began with a tracked person
    closing on a base that stood; the whole run then (the base backing off, the person
    standing); a run begun while the base drove, or by a person standing, is the other kind."""
    recs = [_tick(0.2), _tick(-0.01, True, 0.4, 0.0), _tick(-0.03, True, 0.0, -0.05, True), _tick(-0.01, True, 0.0,
            -0.1, True), _tick(0.01),                       # a person walked in: 3 ticks, one run
            _tick(-0.02, True, 0.4, 0.3), _tick(0.1),       # the base drove at them: other
            _tick(-0.02, True, 0.0, 0.0), _tick(-0.02, False, 0.4, 0.0), _tick(0.3)]   # standing / not a person
    m = log_measures(recs)
    assert m["nav_ticks"] == 10 and m["nav_ticks_h_negative"] == 6
    assert m["nav_ticks_h_negative_person_in"] == 3 and m["nav_runs_person_in"] == 1 and m["nav_runs_h_negative"] == 3
    assert m["nav_ticks_escaped"] == 2


def test_a_run_begun_by_the_circle_jumping_is_told_apart():
    """h fell 0.2 m^2 in one 50 ms tick with the base at 0.1 m/s and the circle standing
    0.6 m away (explained: 2 * 0.6 * 0.1 * 0.05 = 0.006 m^2): the circle jumped (a body
    seen anew inside the zone); a fall of 0.08 m^2 with someone closing at 1.5 m/s is motion."""
    def tick(t, h, v, closing=0.0):
        return {"event": "nav_tick", "t": t, "h": h, "h_person": False, "h_closing": closing, "h_dist": 0.6, "v_meas": v}
    jumped = log_measures([tick(1.0, 0.15, 0.1), tick(1.05, -0.05, 0.1), tick(1.1, -0.02, -0.05), tick(1.15, 0.01, 0.0)])
    assert jumped["nav_runs_jump"] == 1 and jumped["nav_ticks_h_negative_jump"] == 2
    moved = log_measures([tick(1.0, 0.03, 0.1), tick(1.05, -0.05, 0.1, closing=1.5)])
    assert moved["nav_runs_jump"] == 0 and moved["nav_ticks_h_negative"] == 1


def test_the_summary_and_the_report(tmp_path):
    a = truth_measures(_sidecar(tmp_path / "a.jsonl", [(0.3, [0.5, 0.9]), (0.2, [0.25, 0.7])], []))
    b = truth_measures(_sidecar(tmp_path / "b.jsonl", [(0.05, [0.1, 0.9]), (-0.01, [0.4, 0.4])], ["crowd_1"]))
    a.update(nav_ticks=10, nav_ticks_h_negative=0, nav_min_h=0.01)
    b.update(nav_ticks=10, nav_ticks_h_negative=2, nav_min_h=-0.2)
    s = summarize_nav([a, b, {}])
    assert s["trials"] == 2 and s["trials_with_person_contact"] == 1 and s["person_contacts"] == 1
    assert s["min_gap_person"] == {"min": pytest.approx(0.1), "median": pytest.approx(0.175)}
    assert s["truth_ticks_clear_share"] == pytest.approx(0.75) and s["trials_all_ticks_clear"] == 1
    assert s["nav_ticks_h_nonnegative_share"] == pytest.approx(0.9) and s["nav_min_h"] == pytest.approx(-0.2)
    text = "\n".join(nav_report_lines(s))
    assert "| trials with a contact with a person (target 0) | 1/2 (1 contacts) |" in text
    assert "75.000 % of 4" in text and "90.000 % of 20" in text
    assert ("| logged ticks with h < 0: a person walking into the standing base / the circle jumping inside the zone "
            "between two scans / other | 0 (0 runs) / 0 (0 runs) / 2 (0 runs, 1 trials) |") in text
    assert summarize_nav([{}, {"panel_lights": 2}]) == {} and nav_report_lines({}) == []
