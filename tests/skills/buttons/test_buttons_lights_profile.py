"""The light reading (a lamp's colour where the layout and the panel fit put it in the
image) and the profile's buttons: section (defaults, order, checks)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from mmexec.drivers.interfaces import CameraFrame, CameraIntrinsics
from mmexec.skills.buttons.lights import read_light
from mmexec.skills.buttons.profile import (
    ButtonSettings,
    ButtonsSettings,
    MarkerSettings,
    layout,
    ordered,
)
from mmexec.skills.profile import PROFILE

INTR = CameraIntrinsics.from_fov(320, 240, 1.0)


def _frame(colour: tuple[int, int, int], centre_px: tuple[int, int] = (160, 120), r_px: int = 10,
           background: int = 120) -> CameraFrame:
    rgb = np.full((240, 320, 3), background, np.uint8)
    cv2.circle(rgb, centre_px, r_px, colour, -1)
    return CameraFrame(rgb, None, INTR, 0.0, np.eye(4), np.eye(4))


def test_a_green_lamp_is_on_a_dark_one_is_off():
    centre = np.array([0.0, 0.0, 0.5])  # on the optical axis, 0.5 m ahead (camera = map here)
    r = 10 * 0.5 / INTR.fx  # the drawn disk's radius [m]
    on = read_light(_frame((60, 250, 60)), centre, 0.7 * r, 60.0)
    off = read_light(_frame((30, 30, 30)), centre, 0.7 * r, 60.0)
    assert on.on is True and on.excess == pytest.approx(190.0) and on.pixels >= 12
    assert off.on is False and off.excess == pytest.approx(0.0)
    assert on.uv == pytest.approx((INTR.cx, INTR.cy))


def test_a_few_green_pixels_at_the_rim_do_not_count():
    centre = np.array([0.0, 0.0, 0.5])
    r = 10 * 0.5 / INTR.fx
    rgb = _frame((30, 30, 30)).rgb
    cv2.circle(rgb, (160, 120), 10, (60, 250, 60), 2)  # a green ring round a dark lamp
    frame = CameraFrame(rgb, None, INTR, 0.0, np.eye(4), np.eye(4))
    assert read_light(frame, centre, r, 60.0).on is False


def test_a_light_out_of_the_image_or_behind_the_camera_is_not_read():
    f = _frame((60, 250, 60))
    assert read_light(f, np.array([0.0, 0.0, -0.5]), 0.01, 60.0).on is None
    assert read_light(f, np.array([2.0, 0.0, 0.5]), 0.01, 60.0).on is None


def test_defaults_are_the_lab_panel_and_order_is_left_to_right():
    s = ButtonsSettings()
    assert s.validate() == []
    lay = layout(s)
    assert sorted(lay.markers) == [10, 11, 12, 13, 14, 15, 16] and s.locator == 20
    assert ordered(s, None) == ["b1", "b2", "b3"] and ordered(s, ["b3", "b1"]) == ["b3", "b1"]
    with pytest.raises(ValueError, match="no button 'b7' on the panel"):
        ordered(s, ["b7"])
    right_first = ButtonsSettings(buttons=(ButtonSettings("r", (0.1, 0.0, 0.015)), ButtonSettings("l", (-0.1, 0.0, 0.015))))
    assert ordered(right_first, []) == ["l", "r"]


def test_the_section_checks_its_layout():
    bad = ButtonsSettings(locator=10, buttons=(ButtonSettings("a", (0.0, 0.0, 0.01)), ButtonSettings("a", (0.1, 0.0, 0.01))),
                          markers=(MarkerSettings(1, (0.0, 0.0)), MarkerSettings(2, (0.1, 0.0)), MarkerSettings(3, (0.2, 0.0))))
    errs = " / ".join(bad.validate())
    assert "all on one line" in errs and "names must be unique" in errs
    assert PROFILE.sections()["buttons"].package == "mmexec.skills.buttons"
