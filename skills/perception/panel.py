"""A control panel's frame from its ArUco markers, its buttons' poses and the press paths.

The thesis (ros2-thesis-follower-buttons-fruit, section 1.2) puts 7 ArUco markers
(4x4) around 3 buttons on a box; from the markers' poses and their known placement it
computes the buttons' positions in the robot base frame and an end-effector orientation
facing the markers' plane orthogonally. For each button it takes a pose that "sits"
above it at a fixed distance, a linear Cartesian path to the pressed pose (MoveIt 2's
Cartesian path through waypoints, jump threshold 0; the Pilz planner was the most
reliable), and the reversed path to release. Its arm was an Igus Rebel (6 DOF) with a
cylinder presser, later a suction cup, on the flange.

Here:

* :func:`fit_panel` is a rigid fit (Kabsch, :func:`rigid_fit`) of the known marker
  layout to the detected marker centres; the panel's normal is the fitted frame's z.
  It uses every visible marker, not one marker's own orientation (noisy at a distance:
  see ``benchmarks/results/perception.md``). With four or more markers, every
  non-collinear triple is a hypothesis and the one that puts the most markers within
  ``inlier_distance`` wins (ties: the smaller residual), so one wrong marker (a bad
  pose, a misread id) is rejected and the rest are refitted; with exactly three, a
  wrong one can only be caught by the residual (``max_rms``).
* :func:`button_poses` gives each button's cap pose; :func:`press_path` the tool poses
  of the press: the pose above the cap at ``standoff``, straight-line waypoints along the
  normal down to the switch travel plus a small overtravel, and the same waypoints
  reversed to release. The tool orientation is the grasp module's
  :func:`~mmexec.skills.manipulation.grasp.tool_rotation_in_marker` (approach axis into
  the face), so a parallel gripper presses with its closed fingertips. Our planner, not
  MoveIt 2, executes it: :meth:`ArmPlanner.plan_to_pose` to ``above``, then
  :meth:`ArmPlanner.cartesian_path` (IK per waypoint, joint-jump and collision checks)
  to the pressed pose and back; the waypoints are there for a follower that takes a
  list and for checking every one in advance. Put the tool frame at the pressing tip
  (:meth:`ArmKinematics.with_tool_offset`).

Frames: the panel frame follows the marker convention of :mod:`.markers` (origin where
the layout says, x right, y up, z out of the face towards the robot). Marker centres
and every returned pose are in the frame the centres were given in (camera optical
frame, arm base or map). Units: m.
"""

from __future__ import annotations

import itertools
import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from mmexec.drivers.geometry import rigid_fit
from mmexec.skills.manipulation.grasp import tool_rotation_in_marker

__all__ = [
    "Button",
    "PanelFit",
    "PanelFitConfig",
    "PanelFitError",
    "PanelLayout",
    "PressConfig",
    "PressPath",
    "button_poses",
    "fit_panel",
    "press_path",
    "press_paths",
]

log = logging.getLogger(__name__)

Vec3 = tuple[float, float, float]


class PanelFitError(ValueError):
    """The markers seen do not give a panel frame (too few, collinear, or inconsistent
    with the layout)."""


@dataclass(frozen=True)
class Button:
    """A push button: ``position`` [m] of the centre of its cap's top face in the panel
    frame, ``travel`` [m] the cap's stroke until it switches."""

    name: str
    position: Vec3
    travel: float


@dataclass(frozen=True)
class PanelLayout:
    """The panel as built: ``markers`` id -> marker centre [m] in the panel frame (at least
    three, not collinear) and the ``buttons``."""

    markers: Mapping[int, Vec3]
    buttons: tuple[Button, ...]

    def validate(self) -> list[str]:
        """Problems with the layout (empty when usable)."""
        errs = []
        if len(self.markers) < 3:
            errs.append(f"markers: need at least 3, got {len(self.markers)}")
        elif not _spans_plane(np.array(list(self.markers.values()), dtype=float)):
            errs.append("markers: all on one line (the panel's rotation about it is unknown)")
        names = [b.name for b in self.buttons]
        if len(set(names)) != len(names):
            errs.append(f"buttons: names must be unique, got {names}")
        errs += [f"buttons.{b.name}.travel: must be >= 0 m, got {b.travel}" for b in self.buttons if not b.travel >= 0]
        return errs

    def button(self, name: str) -> Button:
        for b in self.buttons:
            if b.name == name:
                return b
        raise KeyError(f"no button {name!r} on the panel (known: {', '.join(b.name for b in self.buttons)})")


@dataclass(frozen=True)
class PanelFitConfig:
    """``inlier_distance`` [m]: a marker whose fitted position is farther from where it
    was seen is rejected. ``max_rms`` [m]: a fit whose inliers' RMS residual is larger is
    refused. ``min_span`` [m]: a triple whose layout triangle is narrower than this
    (height over its longest side) is too close to collinear to be a hypothesis."""

    inlier_distance: float = 0.01
    max_rms: float = 0.006
    min_span: float = 0.02


@dataclass(frozen=True)
class PanelFit:
    """``T_frame_panel`` 4x4; ``inliers`` / ``rejected``: marker ids used / dropped;
    ``rms`` [m] residual of the inliers; ``residuals`` id -> distance [m] between where
    each seen marker was and where the fit puts it."""

    T_frame_panel: np.ndarray
    inliers: tuple[int, ...]
    rejected: tuple[int, ...]
    rms: float
    residuals: Mapping[int, float]

    @property
    def normal(self) -> np.ndarray:
        """Unit normal of the panel face (out of it, towards the robot), in the frame."""
        return self.T_frame_panel[:3, 2].copy()


def _spans_plane(pts: np.ndarray, min_span: float = 1e-6) -> bool:
    """True when the points are not all within ``min_span`` [m] of one line."""
    s = np.linalg.svd(pts - pts.mean(axis=0), compute_uv=False)
    return len(s) > 1 and s[1] / math.sqrt(len(pts)) > min_span


def _triangle_height(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> float:
    sides = [b - a, c - b, a - c]
    longest = max(float(np.linalg.norm(s)) for s in sides)
    return float(np.linalg.norm(np.cross(b - a, c - a))) / max(longest, 1e-12)


def _fit(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """4x4 rigid transform taking the layout points ``src`` onto the seen ``dst``."""
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = rigid_fit(src, dst)
    return T


def _residuals(T: np.ndarray, src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    return np.linalg.norm(src @ T[:3, :3].T + T[:3, 3] - dst, axis=1)


def fit_panel(layout: PanelLayout, centres: Mapping[int, Sequence[float] | np.ndarray],
              config: PanelFitConfig | None = None) -> PanelFit:
    """Panel frame from the seen marker centres (id -> (3,) [m] in any frame); markers
    not in the layout are ignored. Raises :class:`PanelFitError` with fewer than three
    layout markers seen, all seen markers (nearly) collinear, fewer than three consistent
    ones, or an RMS residual above ``max_rms``."""
    cfg = config or PanelFitConfig()
    ids = sorted(i for i in centres if i in layout.markers)
    if len(ids) < 3:
        raise PanelFitError(f"panel: {len(ids)} of its markers seen ({ids}), need 3")
    src = np.array([layout.markers[i] for i in ids], dtype=float)
    dst = np.array([np.asarray(centres[i], dtype=float).reshape(3) for i in ids])
    if not np.all(np.isfinite(dst)):
        raise PanelFitError("panel: a marker centre is not finite")
    # hypotheses: every non-collinear triple; score = (inliers, -sum of their squared residuals)
    best_key: tuple[int, float] | None = None
    inl = np.zeros(len(ids), dtype=bool)
    for tri in itertools.combinations(range(len(ids)), 3):
        sel = list(tri)
        if _triangle_height(*src[sel]) < cfg.min_span:
            continue
        res = _residuals(_fit(src[sel], dst[sel]), src, dst)
        ok = res < cfg.inlier_distance
        if len(ids) == 3:
            ok[:] = True  # nothing to vote with: only max_rms judges three markers
        key = (int(ok.sum()), -float(np.sum(res[ok] ** 2)))
        if best_key is None or key > best_key:
            best_key, inl = key, ok
    if best_key is None:
        raise PanelFitError(f"panel: markers {ids} are (nearly) collinear on the layout")
    if best_key[0] < 3:
        raise PanelFitError(f"panel: no three of markers {ids} agree with the layout within {cfg.inlier_distance} m")
    for _ in range(2):  # refit on the inliers, re-select them, refit
        T = _fit(src[inl], dst[inl])
        res = _residuals(T, src, dst)
        again = res < cfg.inlier_distance
        if len(ids) == 3 or int(again.sum()) < 3 or not _spans_plane(src[again], cfg.min_span / 2):
            break
        inl = again
    T = _fit(src[inl], dst[inl])
    res = _residuals(T, src, dst)
    rms = float(np.sqrt(np.mean(res[inl] ** 2)))
    if rms > cfg.max_rms:
        raise PanelFitError(f"panel: markers {[ids[k] for k in np.flatnonzero(inl)]} fit the layout with "
                            f"{rms * 1e3:.1f} mm RMS (max {cfg.max_rms * 1e3:.1f} mm)")
    rejected = tuple(ids[k] for k in np.flatnonzero(~inl))
    if rejected:
        log.info("panel: markers %s rejected (residuals %s m)", rejected,
                 [round(float(res[k]), 4) for k in np.flatnonzero(~inl)])
    return PanelFit(T, tuple(ids[k] for k in np.flatnonzero(inl)), rejected, rms,
                    {i: float(r) for i, r in zip(ids, res)})


def button_poses(T_frame_panel: np.ndarray, layout: PanelLayout) -> dict[str, np.ndarray]:
    """Button name -> 4x4 pose of its cap (origin at the centre of the cap's top face,
    axes the panel's: z out of the face) in the panel fit's frame."""
    out = {}
    for b in layout.buttons:
        T = np.eye(4)
        T[:3, 3] = b.position
        out[b.name] = np.asarray(T_frame_panel, dtype=float) @ T
    return out


@dataclass(frozen=True)
class PressConfig:
    """``standoff`` [m]: the tool tip's distance from the cap in the pose above it.
    ``overtravel`` [m]: pressed beyond the button's travel. ``step`` [m]: the largest
    spacing of the straight-line waypoints."""

    standoff: float = 0.08
    overtravel: float = 0.003
    step: float = 0.01

    def validate(self) -> list[str]:
        errs = []
        if not self.standoff > 0:
            errs.append(f"standoff: must be > 0 m, got {self.standoff}")
        if not self.overtravel >= 0:
            errs.append(f"overtravel: must be >= 0 m, got {self.overtravel}")
        if not self.step > 0:
            errs.append(f"step: must be > 0 m, got {self.step}")
        return errs


@dataclass(frozen=True)
class PressPath:
    """Tool poses (4x4) for pressing one button, in the frame of the button pose: ``above``
    (facing the cap at the standoff), ``press`` (N, 4, 4) straight-line waypoints from
    ``above`` (first) to the pressed pose (last, ``depth`` [m] below the cap's rest
    position), ``release`` the same waypoints reversed."""

    button: str
    above: np.ndarray
    press: np.ndarray
    release: np.ndarray
    depth: float

    @property
    def pressed(self) -> np.ndarray:
        return self.press[-1]


def press_path(T_frame_button: np.ndarray, approach_axis: int, *, travel: float, name: str = "",
               config: PressConfig | None = None) -> PressPath:
    """The press of one button whose cap pose is ``T_frame_button`` (z out of the face):
    the tool's ``approach_axis`` (0 = x, WX250s; 2 = z, UR) points into the face along
    the normal, the tool origin (its pressing tip) moves on the normal from
    ``standoff`` above the cap to ``travel + overtravel`` below it and back."""
    cfg = config or PressConfig()
    errs = cfg.validate() + ([] if travel >= 0 else [f"travel: must be >= 0 m, got {travel}"])
    if errs:
        raise ValueError("PressConfig: " + "; ".join(errs))
    depth = travel + cfg.overtravel
    length = cfg.standoff + depth
    z = np.linspace(cfg.standoff, -depth, math.ceil(length / cfg.step - 1e-9) + 1)
    local = np.tile(np.eye(4), (len(z), 1, 1))
    local[:, :3, :3] = tool_rotation_in_marker(approach_axis)
    local[:, 2, 3] = z
    press = np.asarray(T_frame_button, dtype=float) @ local
    return PressPath(name, press[0].copy(), press, press[::-1].copy(), depth)


def press_paths(fit: PanelFit, layout: PanelLayout, approach_axis: int, order: Sequence[str] | None = None,
                config: PressConfig | None = None) -> list[PressPath]:
    """:func:`press_path` for the layout's buttons (``order`` by name; default all, in
    layout order) on the fitted panel."""
    poses = button_poses(fit.T_frame_panel, layout)
    buttons = [layout.button(n) for n in order] if order is not None else list(layout.buttons)
    return [press_path(poses[b.name], approach_axis, travel=b.travel, name=b.name, config=config) for b in buttons]
