"""locate_panel and press_buttons on the mock backend: the panel's markers rendered from
the base camera and fitted, then each button pressed by the mock arm (planned for real:
IK per waypoint of the straight line, OMPL to the pose above) and its light, which a mock
panel latches when the pressing tip really goes past 70 % of the travel inside the cap,
read back from the camera image."""

from __future__ import annotations

import math

import numpy as np
import pytest
from buttonkit import MockPanel, PanelCamera, events_of, offset, panel_pose, run_skill

from mmexec.skills.base import FailureKind, SkillStatus
from mmexec.skills.buttons.panel import WORLD_DONE, WORLD_PANEL, PanelEstimate
from mmexec.skills.buttons.profile import ButtonsSettings, buttons_settings


def _rig(ctx, robot, dead=()):
    """A panel 0.46 m in front of the base, its face centre 0.45 m up, facing the robot;
    its markers and lights on the camera."""
    p = robot.base.pose
    T = panel_pose(p.x + 0.46, p.y, 0.45, math.pi)
    s: ButtonsSettings = buttons_settings(ctx)
    panel = MockPanel(robot, s, T, dead=dead)
    robot.camera = PanelCamera(robot, {m.id: offset(T, *m.position) for m in s.markers}, panel)
    return T, panel


def _located(ctx, robot, dead=()):
    T, panel = _rig(ctx, robot, dead)
    guess = offset(T, 0.02, -0.01)  # a locator estimate a little off
    ctx.world[WORLD_PANEL] = PanelEstimate(guess, "locator")
    run = run_skill(ctx, "locate_panel")
    assert run.status is SkillStatus.SUCCESS, run.failure
    return T, panel, run


def test_locate_panel_fits_the_seen_markers(ctx, robot):
    T, _, run = _located(ctx, robot)
    est = ctx.world[WORLD_PANEL]
    assert est.source == "fit" and sorted(run.outputs["markers"]) == [10, 11, 12, 13, 14, 15, 16]
    assert np.linalg.norm(est.T_map_panel[:3, 3] - T[:3, 3]) < 0.005
    assert float(est.T_map_panel[:3, 2] @ T[:3, 2]) > math.cos(math.radians(2))


def test_press_buttons_presses_each_one_left_to_right_along_the_normal(ctx, robot):
    _, panel, _ = _located(ctx, robot)
    followed = []
    follow = robot.arm.follow
    robot.arm.follow = lambda traj: (followed.append(traj), follow(traj))[1]
    run = run_skill(ctx, "press_buttons", panel=panel)
    assert run.status is SkillStatus.SUCCESS, run.failure
    assert run.outputs["outcomes"] == {"b1": "pressed", "b2": "pressed", "b3": "pressed"}
    assert run.outputs["pressed"] == ["b1", "b2", "b3"] and run.outputs["trajectories"] == "6/6"
    assert panel.lit == {"b1", "b2", "b3"}
    for name, depth in panel.depth.items():  # travel 6 mm + overtravel 3 mm, on the estimated cap
        assert 0.006 < depth < 0.013, (name, depth)
    # above, press, release per button: the straight lines have no joint jump
    assert len(followed) == 9
    for traj in followed[1::3] + followed[2::3]:
        q = np.array(traj.positions)
        assert np.abs(np.diff(q, axis=0)).max() < 0.15
    presses = events_of(ctx, "button_press")
    assert [e["button"] for e in presses] == ["b1", "b2", "b3"]
    assert all(e["light_before"] is False and e["light_after"] is True for e in presses)
    for tr in events_of(ctx, "press_trajectory"):
        for phase in ("press", "release"):
            pts = np.array(tr[phase]["planned"])[:, 1:]  # [x, y, z] mm in the button frame
            assert np.abs(pts[:, :2]).max() < 1.0, (tr["button"], phase)  # straight, on the normal
            z = pts[:, 2]
            ends = (z[0], z[-1]) if phase == "press" else (z[-1], z[0])
            assert ends == (pytest.approx(80.0, abs=1.0), pytest.approx(-9.0, abs=1.0))
            assert np.all(np.diff(z) < 1e-6) if phase == "press" else np.all(np.diff(z) > -1e-6)
            assert len(tr[phase]["executed"]) > 3


def test_requested_order_and_an_unknown_button(ctx, robot):
    _, panel, _ = _located(ctx, robot)
    run = run_skill(ctx, "press_buttons", {"buttons": ["b3", "b1"]}, panel=panel)
    assert run.status is SkillStatus.SUCCESS, run.failure
    assert [e["button"] for e in events_of(ctx, "button_press")] == ["b3", "b1"] and panel.lit == {"b1", "b3"}
    run = run_skill(ctx, "press_buttons", {"buttons": ["b9"]}, panel=panel)
    assert run.failure is not None and run.failure.kind is FailureKind.PRECONDITION
    assert "no button 'b9'" in run.failure.reason and "b1, b2, b3" in run.failure.reason


def test_a_button_whose_light_stays_off_fails_naming_it(ctx, robot):
    _, panel, _ = _located(ctx, robot, dead=("b2",))
    run = run_skill(ctx, "press_buttons", panel=panel)
    assert run.failure is not None and run.failure.kind is FailureKind.POSTCONDITION
    assert run.failure.reason == "light off after pressing b2 (not lit)"
    assert panel.depth["b2"] > 0.006  # it was pressed, it did not switch
    assert ctx.world[WORLD_DONE] == {"b1", "b3"}


def test_a_retry_does_not_press_a_lit_button_again(ctx, robot):
    _, panel, _ = _located(ctx, robot)
    ctx.world[WORLD_DONE] = {"b1"}
    run = run_skill(ctx, "press_buttons", panel=panel)
    assert run.status is SkillStatus.SUCCESS, run.failure
    assert [e["button"] for e in events_of(ctx, "button_press")] == ["b2", "b3"]
    assert panel.depth["b1"] == 0.0 and run.outputs["pressed"] == ["b1", "b2", "b3"]


def test_press_needs_a_fitted_panel(ctx, robot):
    ctx.world[WORLD_PANEL] = PanelEstimate(np.eye(4), "locator")
    run = run_skill(ctx, "press_buttons")
    assert run.failure is not None and run.failure.kind is FailureKind.PRECONDITION
    assert "locate_panel" in run.failure.reason


def test_too_few_markers_seen_fails_the_fit(ctx, robot):
    T, _ = _rig(ctx, robot)
    robot.camera.markers = {k: v for k, v in list(robot.camera.markers.items())[:2]}
    ctx.world[WORLD_PANEL] = PanelEstimate(T, "locator")
    run = run_skill(ctx, "locate_panel")
    assert run.failure is not None and run.failure.kind is FailureKind.EXECUTION
    assert "2 of its markers seen" in run.failure.reason


def test_a_camera_that_goes_silent_fails_the_look_instead_of_hanging(ctx, robot, monkeypatch):
    """locate_panel waited for its frames with no deadline: a camera that stopped hung the
    skill (and the mission) for good. Now every frame wait has the 2 s deadline of
    perception.detect.next_frame."""
    T, _ = _rig(ctx, robot)
    monkeypatch.setattr(robot.camera, "frame", lambda: None)
    ctx.world[WORLD_PANEL] = PanelEstimate(T, "locator")
    run = run_skill(ctx, "locate_panel", max_ticks=2000)  # 100 s of clock at 20 Hz: far past the deadline
    assert run.status is SkillStatus.FAILURE
    assert run.failure is not None and run.failure.kind is FailureKind.EXECUTION
    assert "camera gave no frame for 2 s" in run.failure.reason
