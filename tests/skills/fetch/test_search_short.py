"""The search goes back to a location the drive stopped short of (skills/search.py,
``SHORT_AGAIN``): with the local planner, a viewpoint drive held back by people looks from
up to 0.8 m short of a search location; from there a small marker can be out of the
camera's range. When the marker is not found anywhere, those locations are searched once
more before the search fails. On the mock: the first drive to search location 1 stops
0.5 m short (as people would hold it), the marker is in range only from the location."""

from __future__ import annotations

import math

from fetchkit import events_of, marker_pose, run_skill

import mmexec.skills.search as search_mod
from mmexec.drivers.interfaces import Pose2D
from mmexec.skills.base import SkillStatus
from mmexec.skills.search import WORLD_SEARCH


class _NoPeople:
    """A people watch that sees nobody (the local planner's tracks, empty)."""

    def observe(self) -> None:
        pass

    def in_view(self) -> int:
        return 0


def _held_back_once(monkeypatch, robot, label: str, short: float) -> list[str]:
    """The first drive to ``label`` ends ``short`` [m] before its goal, as a viewpoint drive
    people hold back does; every other drive is the real one. Returns the labels driven to."""
    real = search_mod.drive_path
    driven: list[str] = []

    def drive(ctx, goal, lbl, **kw):
        driven.append(lbl)
        if lbl == label and driven.count(lbl) == 1:
            p = robot.base.pose
            d = math.hypot(goal.x - p.x, goal.y - p.y)
            f = (d - short) / d
            stop = Pose2D(p.x + f * (goal.x - p.x), p.y + f * (goal.y - p.y), goal.theta)
            yield from real(ctx, stop, lbl, **kw)
            return robot.base.pose
        return (yield from real(ctx, goal, lbl, **kw))

    monkeypatch.setattr(search_mod, "drive_path", drive)
    monkeypatch.setattr(search_mod._PeopleWatch, "for_robot", classmethod(lambda cls, ctx: _NoPeople()))
    return driven


def test_a_location_looked_at_from_short_of_it_is_searched_again(monkeypatch, fetch_robot, fetch_ctx):
    # only visible from the first search location (4, 1), facing +x there, within 1.5 m
    fetch_robot.camera.markers = {6: marker_pose(5.2, 1.0, 0.5, math.pi)}
    fetch_robot.camera.max_range = 1.5
    driven = _held_back_once(monkeypatch, fetch_robot, "search location 1", 0.5)
    run = run_skill(fetch_ctx, "search", {"marker": 6})
    assert run.status is SkillStatus.SUCCESS, run.failure
    # the start, location 1 (0.5 m short: 1.7 m from the marker), location 2, then
    # location 1 again, where the first view finds it
    assert driven == ["search location 1", "search location 2", "search location 1"]
    assert [e["short"] for e in events_of(fetch_ctx, "search_second_pass")] == [1]
    assert [e["locations"] for e in events_of(fetch_ctx, "search_second_pass")] == [1]
    assert run.outputs["views"] == 12 * 3 + 1
    pose = fetch_robot.base.pose
    assert abs(pose.x - 4.0) < 0.06 and abs(pose.y - 1.0) < 0.06


def test_a_location_reached_is_not_searched_again(monkeypatch, fetch_robot, fetch_ctx):
    fetch_robot.camera.markers = {}
    driven = _held_back_once(monkeypatch, fetch_robot, "no such location", 0.5)
    run = run_skill(fetch_ctx, "search", {"marker": 9})
    assert run.status is SkillStatus.FAILURE
    assert driven == ["search location 1", "search location 2"]
    assert not events_of(fetch_ctx, "search_second_pass")
    assert fetch_ctx.world[WORLD_SEARCH].short == []
    assert "36 views at 3 locations" in run.failure.reason
