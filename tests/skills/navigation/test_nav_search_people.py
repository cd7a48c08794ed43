"""The search skill with people in the camera's way (issue 12): with ``nav.local_planner``
the lidar's tracked people are watched; a view with someone walking in front of the
camera waits for them and looks again, and a search that found nothing while people
stood in its views goes over its locations once more before it fails. Mock base, camera
(which never sees a marker) and a ray-cast lidar with a person pacing in front."""

from __future__ import annotations

import math
from typing import Any

import pytest
from test_nav_local_drive import ScanLidar, room

import mmexec.skills.search  # registers search
from mmexec.drivers.interfaces import Pose2D
from mmexec.drivers.mock.robot import MockRobot
from mmexec.skills.base import SkillContext, SkillStatus, run_skill
from mmexec.skills.search import OCCLUSION_WAIT

#: [s] when the pacing person leaves: the base reaches the search location at about 15 s
#: of clock and its first view there waits for them
STOP = 18.0


class PacingLidar(ScanLidar):
    """The scan with a person (radius 0.2 m) pacing along x = ``x`` between y = 1.0 and
    2.0 m at 0.6 m/s from ``start`` [s] on (until then, and after ``stop``, out of the
    room's way at y = 2.7)."""

    def __init__(self, robot: MockRobot, x: float, start: float = 0.0, stop: float = math.inf) -> None:
        super().__init__(robot, room())
        self.x, self.start, self.stop = x, start, stop

    def scan(self) -> Any:
        t = self._robot.clock.now()
        if self.start <= t < self.stop:
            phase = (0.6 * (t - self.start)) % 2.0
            y = 1.0 + (phase if phase <= 1.0 else 2.0 - phase)
            self.circles = [(self.x, y, 0.2)]
        else:
            self.circles = []
        return super().scan()


def _search(lidar_x: float | None, events: list[tuple[str, dict[str, Any]]], **walk: float) -> Any:
    profile = {"nav": {"local_planner": True, "max_v": 0.5, "max_w": 2.0, "accel_v": 1.0, "accel_w": 3.5,
                       "timeout": 60.0},
               "search": {"locations": [[4.5, 1.5, 0.0]], "step_deg": 90.0, "settle_time": 0.2},
               "camera": {"detect_frames": 1}}
    robot = MockRobot(profile=profile, capabilities={"base", "camera", "lidar"})
    robot.base.pose = Pose2D(1.0, 1.5, 0.0)
    robot.occupancy = room()
    robot.lidar = PacingLidar(robot, lidar_x if lidar_x is not None else -5.0, **walk)
    ctx = SkillContext.for_robot(robot, emit=lambda event, **f: events.append((event, {**f, "t": robot.clock.now()})))
    return run_skill("search", ctx, {"marker": 7}, step=lambda: robot.spin(0.05), max_ticks=20000)


def _of(events: list[tuple[str, dict[str, Any]]], name: str) -> list[dict[str, Any]]:
    return [f for e, f in events if e == name]


def test_nobody_in_the_way_one_pass():
    events: list[tuple[str, dict[str, Any]]] = []
    run = _search(None, events)
    assert run.status is SkillStatus.FAILURE
    assert run.failure.reason == "marker 7 not found: 8 views at 2 locations"
    assert not _of(events, "search_occluded") and not _of(events, "search_second_pass")


def test_a_person_pacing_in_front_of_the_camera_is_waited_for_then_searched_past_again(monkeypatch):
    """Someone paces 0.8 m in front of the camera at the search location (in its cone all the time),
    and the search may not step aside (MAX_SIDESTEPS 0):
    the views facing them wait OCCLUSION_WAIT and count as hidden; the marker is not
    found (the mock camera sees none), so the search goes over its location once more
    and fails saying people were in the way."""
    monkeypatch.setattr(mmexec.skills.search, "MAX_SIDESTEPS", 0)
    events: list[tuple[str, dict[str, Any]]] = []
    run = _search(5.3, events)
    assert run.status is SkillStatus.FAILURE
    occluded = _of(events, "search_occluded")
    assert occluded and not occluded[0]["cleared"] and occluded[0]["waited"] >= OCCLUSION_WAIT - 0.06
    (second,) = _of(events, "search_second_pass")
    assert second["locations"] == 1 and second["occluded"] == 1 and len(occluded) == 2
    assert "people in the way of" in run.failure.reason and "12 views" in run.failure.reason


def test_a_person_who_walks_off_is_waited_for_and_the_view_looked_at_again():
    """The same person leaves at STOP: the wait ends when the cone clears (before
    OCCLUSION_WAIT runs out), the view is looked at again, and with nobody left in the
    way there is no second pass."""
    events: list[tuple[str, dict[str, Any]]] = []
    run = _search(5.3, events, stop=STOP)
    (occluded,) = _of(events, "search_occluded")
    assert occluded["cleared"] and occluded["waited"] < OCCLUSION_WAIT
    assert occluded["t"] == pytest.approx(STOP, abs=0.6)            # cleared within a few scans of leaving
    assert not _of(events, "search_second_pass") and run.failure.reason.endswith("people in the way of 1 views")


def test_a_person_who_stays_in_front_of_the_camera_is_looked_past_from_a_step_aside():
    """The same person pacing 0.8 m ahead, and the search may step aside: after the wait
    the base steps SIDESTEP square to its heading, away from the side the person stood
    on, keeps its heading, and looks from there, where the person no longer fills the
    view; with nobody left in the way there is no second pass."""
    from mmexec.skills.search import SIDESTEP

    events: list[tuple[str, dict[str, Any]]] = []
    run = _search(5.3, events)
    assert run.status is SkillStatus.FAILURE
    (occluded,) = _of(events, "search_occluded")
    assert occluded["sidestep"] in ("left", "right") and occluded["cleared"]
    assert occluded["waited"] >= OCCLUSION_WAIT
    goals = [f for f in _of(events, "base_status") if f.get("label") == "search sidestep"]
    assert len(goals) == 1
    x, y, theta = goals[0]["goal"]
    assert x == pytest.approx(4.5, abs=0.03) and abs(y - 1.5) == pytest.approx(SIDESTEP, abs=0.03)
    assert theta == pytest.approx(0.0, abs=0.05)
    assert not _of(events, "search_second_pass") and run.failure.reason.endswith("people in the way of 1 views")
