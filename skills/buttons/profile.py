"""The robot profile's ``buttons:`` section: the control panel as built (its markers, its
buttons and their lights, the locator marker), where the base parks in front of it, how
the arm looks at it and presses, and the calibrated tool offset of the pressing tip.

Declared in :mod:`mmexec.skills.profile`, so a config's mistakes are reported when it
loads (``FILE:LINE:COL: profile.buttons.key: message``). Every default describes the
panel of the ``lab`` world (sim/worlds/lab.yaml): a 0.4 x 0.3 m face with seven
DICT_4X4 markers (ids 10..16), three buttons of 20 / 30 / 40 mm (b1, b2, b3, left to
right) with a light above each, and the locator marker 20 on the stand.

Panel frame (the marker convention, :mod:`mmexec.skills.perception.panel`): origin at the
face centre, x right as seen from the front, y up, z out of the face. Units: m, deg.
"""

from __future__ import annotations

from dataclasses import dataclass

from mmexec.skills.base import SkillContext
from mmexec.skills.perception.panel import Button, PanelFitConfig, PanelLayout, PressConfig
from mmexec.skills.profile import declare_settings, setting

__all__ = ["ButtonSettings", "ButtonsSettings", "MarkerSettings", "buttons_settings", "layout", "light_of", "ordered"]


@dataclass(frozen=True)
class ButtonSettings:
    """One button as built: cap centre ``position`` [x, y, z] in the panel frame (z: how
    far the cap stands out of the face), ``travel`` to its switch point, its light's
    centre ``light`` [x, y] on the face and ``light_diameter``."""

    name: str = setting(doc="the button's name (requests name it)")
    position: tuple[float, float, float] = setting(unit="m", doc="cap top centre in the panel frame")
    diameter: float = setting(0.03, unit="m", gt=0, doc="cap diameter")
    travel: float = setting(0.006, unit="m", gt=0, le=0.05, doc="cap travel to the switch point")
    light: tuple[float, float] = setting((0.0, 0.06), unit="m", doc="its light's centre [x, y] on the face")
    light_diameter: float = setting(0.02, unit="m", gt=0, doc="its light's diameter")


@dataclass(frozen=True)
class MarkerSettings:
    """A panel marker as built: ``id`` and centre ``position`` [x, y] on the face."""

    id: int = setting(ge=0, le=49, doc="ArUco id")
    position: tuple[float, float] = setting(unit="m", doc="centre [x, y] on the face, panel frame")


_LAB_MARKERS = tuple(MarkerSettings(i, xy) for i, xy in (
    (10, (-0.165, 0.11)), (11, (0.0, 0.11)), (12, (0.165, 0.11)), (13, (-0.165, -0.11)),
    (14, (-0.055, -0.11)), (15, (0.055, -0.11)), (16, (0.165, -0.11))))
_LAB_BUTTONS = (ButtonSettings("b1", (-0.1, -0.035, 0.015), 0.02, 0.006, (-0.1, 0.045)),
                ButtonSettings("b2", (0.0, -0.035, 0.015), 0.03, 0.006, (0.0, 0.045)),
                ButtonSettings("b3", (0.1, -0.035, 0.015), 0.04, 0.006, (0.1, 0.045)))


@dataclass(frozen=True)
class ButtonsSettings:
    """The ``buttons:`` section (docs/buttons.md)."""

    locator: int = setting(20, ge=0, le=49, doc="id of the locator marker that tells where the panel is")
    locator_position: tuple[float, float] = setting((0.0, -0.35), unit="m",
                                                    doc="locator centre [x, y] in the face plane, panel frame")
    markers: tuple[MarkerSettings, ...] = setting(_LAB_MARKERS, doc="the panel's markers as built")
    buttons: tuple[ButtonSettings, ...] = setting(_LAB_BUTTONS, doc="the buttons as built")
    body: tuple[float, float, float] = setting((0.4, 0.3, 0.15), unit="m", gt=0,
                                               doc="panel box [width, height, depth], added to the planning scene")
    standoff: float = setting(0.9, unit="m", gt=0.2, le=3.0,
                              doc="base centre to the panel face when parked in front of it")
    retry_shift: float = setting(0.05, unit="m", ge=0, le=0.3,
                                 doc="a repositioning parks this much nearer, then farther, than standoff")
    search_locations: list[tuple[float, float, float]] = setting([], unit="m, m, rad", base_pose=True, doc=(
        "base poses [x, y, theta] in map find_panel searches from after the current one (empty: "
        "profile search.locations)"))
    sweep: tuple[str, ...] = setting(("look",), refers_to="named_poses",
                                     doc="arm poses the wrist camera looks from while searching for the locator")
    sweep_pan_deg: tuple[float, ...] = setting((0.0, 50.0, -50.0), unit="deg",
                                               doc="first-joint turns added to each sweep pose, in order")
    turn_deg: float = setting(120.0, unit="deg", ge=10, le=180,
                              doc="base turn between two sweeps (counter-clockwise)")
    views: tuple[tuple[float, float, float, float], ...] = setting(
        ((0.0, 0.0, 0.4, 90.0), (0.0, 0.0, 0.4, -90.0), (0.0, 0.06, 0.45, 0.0)), doc=(
            "camera views of the panel [dx, dy (m, the aimed point from the face centre), distance (m, "
            "camera to face), roll (deg)], tried in order until min_markers are seen"))
    min_markers: int = setting(5, ge=3, doc="markers to see before fitting without trying further views")
    tool_offset: tuple[float, float, float] = setting((0.0, 0.0, 0.012), unit="m", doc=(
        "the pressing tip in the arm's tool frame (the grasp point; approach axis z on the UR): the "
        "calibrated offset that absorbs the arm's and the gripper's systematic error"))
    press_standoff: float = setting(0.08, unit="m", gt=0, le=0.3, doc="tip to cap in the pose above a button")
    overtravel: float = setting(0.003, unit="m", ge=0, le=0.02, doc="pressed beyond the button's travel")
    step: float = setting(0.01, unit="m", gt=0, le=0.05, doc="spacing of the straight-line waypoints")
    max_joint_step: float = setting(0.15, unit="rad", gt=0, le=1.0,
                                    doc="largest joint change between two waypoints of a press line")
    inlier_distance: float = setting(0.01, unit="m", gt=0, doc="panel fit: a marker farther off is rejected")
    max_rms: float = setting(0.006, unit="m", gt=0, doc="panel fit: refused above this RMS residual")
    light_contrast: float = setting(60.0, ge=1, le=255, doc=(
        "a light is on when its pixels' green exceeds their red and blue by this much (0-255 levels)"))

    def validate(self) -> list[str]:
        errs = layout(self).validate()
        names = [b.name for b in self.buttons]
        if not self.buttons:
            errs.append("buttons: the panel needs at least one button")
        if self.locator in [m.id for m in self.markers]:
            errs.append(f"locator: marker {self.locator} is also a panel marker")
        if len(set(names)) != len(names):
            errs.append(f"buttons: names must be unique, got {names}")
        if not self.views:
            errs.append("views: give at least one camera view of the panel")
        if len(self.sweep) * len(self.sweep_pan_deg) == 0:
            errs.append("sweep, sweep_pan_deg: give at least one pose and one turn")
        return errs

    def fit_config(self) -> PanelFitConfig:
        return PanelFitConfig(inlier_distance=self.inlier_distance, max_rms=self.max_rms)

    def press_config(self) -> PressConfig:
        return PressConfig(standoff=self.press_standoff, overtravel=self.overtravel, step=self.step)


buttons_settings = declare_settings("buttons", ButtonsSettings, package="mmexec.skills.buttons",
                                    doc="the button presser: the panel as built, parking, views, press, tool offset")


def layout(s: ButtonsSettings) -> PanelLayout:
    """The panel as :mod:`mmexec.skills.perception.panel` fits it (markers on the face, z 0)."""
    return PanelLayout({int(m.id): (float(m.position[0]), float(m.position[1]), 0.0) for m in s.markers},
                       tuple(Button(b.name, tuple(b.position), b.travel) for b in s.buttons))


def light_of(s: ButtonsSettings, name: str) -> ButtonSettings:
    for b in s.buttons:
        if b.name == name:
            return b
    raise KeyError(name)


def ordered(s: ButtonsSettings, names: list[str] | None) -> list[str]:
    """The requested button names, checked; none requested: all, left to right."""
    known = [b.name for b in sorted(s.buttons, key=lambda b: b.position[0])]
    if not names:
        return known
    bad = [n for n in names if n not in known]
    if bad:
        raise ValueError(f"no button {', '.join(map(repr, bad))} on the panel (buttons: {', '.join(known)})")
    return [str(n) for n in names]


def settings(ctx: SkillContext) -> ButtonsSettings:
    """The bound ``profile.buttons`` section."""
    return buttons_settings(ctx)
