"""Control panels with spring-loaded push buttons and lights (the ROS 2 thesis's button
presser, section 1.2): declared in a world file's ``panels:`` section, spawned into
pybullet, stepped with the physics, and measured (sim-only ground truth).

A panel is a box (``size`` [width, height, depth], default 0.4 x 0.3 x 0.15 m) on a stand,
its face vertical and facing ``pose`` yaw, the face centre ``height`` above the floor. Its
frame follows the marker convention (:mod:`mmexec.skills.perception.panel`): origin at the
face centre, x right as seen from the front, y up, z out of the face. On the face:

* ``buttons``: caps of ``diameter`` standing ``cap_height`` out of the face, each on a
  prismatic joint pushed back out by a force-limited motor (a spring of ``force`` [N]);
  the cap travels ``travel`` to its switch point and ``stroke`` to its hard stop. A cap
  pushed past ``PRESS_FRACTION`` (70 %) of ``travel`` switches its **light** on, and the
  light stays on (a latching indicator, like a "call acknowledged" lamp), so a robot can
  check afterwards, with its camera, that the press took;
* ``markers``: ArUco DICT_4X4_50 markers (``marker_size`` black square, printed with a
  one-cell white border) at known positions, the thesis's seven;
* ``locator``: one larger marker on the stand's front, in the face plane, that tells
  from across the room where the panel is.

The stand and the box are static parts of the world (:meth:`World.static_boxes`, kind
``panel``): in the physics world, the lidar's view and the navigation map, but not in the
arm's planning scene: the panel can be moved, so a robot adds it from what it sees.

Ground truth (never for skills): :class:`SimPanels` records every press of a cap (from
first touch to release) as a :class:`Press`: the deepest travel, whether it switched, and
the **press point**'s offset from the button's centre, the centre of the robot links
touching the cap (their bounding boxes' centre) in the face plane, at the deepest travel.
The truth log (:mod:`mmexec.sim.truth`) writes them as ``panel_press`` records and the
lights at the end as ``panel_end``.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mmexec.drivers.geometry import planar_transform, position_quat

__all__ = [
    "PRESS_FRACTION",
    "Panel",
    "PanelButton",
    "PanelLocator",
    "PanelMarker",
    "Press",
    "SimPanels",
    "panel_boxes",
    "panel_transform",
]

log = logging.getLogger(__name__)

#: a cap pushed past this fraction of its ``travel`` switches its light on
PRESS_FRACTION = 0.7
#: [m] a cap depressed more than this is being pressed (a press starts and ends here)
TOUCH_DEPTH = 0.0005
#: light colours (RGBA): off, on
LIGHT_OFF = (0.12, 0.12, 0.12, 1.0)
LIGHT_ON = (0.25, 1.0, 0.25, 1.0)
HOUSING_COLOR = (0.55, 0.57, 0.6, 1.0)


@dataclass(frozen=True)
class PanelButton:
    """A push button: ``position`` [x, y] of its centre on the face (panel frame, m),
    cap ``diameter`` [m], standing ``cap_height`` [m] out of the face at rest; ``travel``
    [m] to the switch point (pressed past 70 % of it), ``stroke`` [m] to the hard stop;
    the return spring pushes with ``force`` [N]; its light's centre ``light`` [x, y] and
    ``light_diameter`` [m]; cap ``color`` RGB."""

    name: str
    position: tuple[float, float]
    diameter: float = 0.03
    travel: float = 0.006
    stroke: float = 0.010
    cap_height: float = 0.015
    force: float = 3.0
    light: tuple[float, float] = (0.0, 0.06)
    light_diameter: float = 0.02
    color: tuple[float, float, float] = (0.85, 0.15, 0.1)

    def validate(self) -> list[str]:
        out = []
        if min(self.diameter, self.travel, self.cap_height, self.force, self.light_diameter) <= 0:
            out.append(f"button {self.name!r}: diameter, travel, cap_height, force and light_diameter must be > 0")
        if not self.travel <= self.stroke < self.cap_height:
            out.append(f"button {self.name!r}: needs travel <= stroke < cap_height, got {self.travel}, {self.stroke}, "
                       f"{self.cap_height}")
        return out


@dataclass(frozen=True)
class PanelMarker:
    """An ArUco DICT_4X4_50 marker (``id`` 0..49) centred at ``position`` [x, y] on the face [m]."""

    id: int
    position: tuple[float, float]


@dataclass(frozen=True)
class PanelLocator:
    """The locator marker: ``id``, centre ``position`` [x, y] in the face plane (on the
    stand's front, below the box) and black-square ``size`` [m]."""

    id: int
    position: tuple[float, float] = (0.0, -0.35)
    size: float = 0.12


@dataclass(frozen=True)
class Panel:
    """A control panel on a stand (module doc): ``pose`` [x, y, yaw] of the face centre in
    ``map`` (yaw: the way the face looks), the face centre ``height`` [m] above the floor,
    box ``size`` [width, height, depth] [m], stand ``stand`` [width, depth] [m] (its front
    flush with the face), marker ``marker_size`` [m]."""

    name: str
    pose: tuple[float, float, float]
    height: float = 0.75
    size: tuple[float, float, float] = (0.4, 0.3, 0.15)
    stand: tuple[float, float] = (0.25, 0.15)
    marker_size: float = 0.045
    buttons: tuple[PanelButton, ...] = ()
    markers: tuple[PanelMarker, ...] = ()
    locator: PanelLocator | None = None

    def validate(self) -> list[str]:
        out: list[str] = []
        w, h, d = self.size
        if min(w, h, d, *self.stand, self.marker_size) <= 0:
            out.append(f"panel {self.name!r}: size, stand and marker_size must be > 0")
            return out
        if not h / 2 < self.height:
            out.append(f"panel {self.name!r}: height {self.height} m puts the box ({h} m tall) into the floor")
        names = [b.name for b in self.buttons]
        if len(set(names)) != len(names):
            out.append(f"panel {self.name!r}: button names must be unique, got {names}")
        ids = [m.id for m in self.markers] + ([self.locator.id] if self.locator else [])
        if len(set(ids)) != len(ids):
            out.append(f"panel {self.name!r}: marker ids must be unique, got {ids}")
        out += [f"panel {self.name!r}: marker {i} outside DICT_4X4_50 ids 0..49" for i in ids if not 0 <= i < 50]
        half = self.marker_size * 8 / 6 / 2
        for m in self.markers:
            if abs(m.position[0]) + half > w / 2 + 1e-9 or abs(m.position[1]) + half > h / 2 + 1e-9:
                out.append(f"panel {self.name!r}: marker {m.id} at {list(m.position)} does not fit the {w} x {h} m face")
        for b in self.buttons:
            for x, y, r, what in ((*b.position, b.diameter / 2, "cap"), (*b.light, b.light_diameter / 2, "light")):
                if abs(x) + r > w / 2 or abs(y) + r > h / 2:
                    out.append(f"panel {self.name!r}: button {b.name!r}'s {what} at [{x}, {y}] is off the face")
        if self.locator is not None:
            lx, ly = self.locator.position
            lh = self.locator.size * 8 / 6 / 2
            stand_h = self.height - h / 2
            if abs(lx) + lh > self.stand[0] / 2 + 1e-9 or not -(self.height - lh) <= ly <= -(h / 2 + lh) + 1e-9:
                out.append(f"panel {self.name!r}: locator at {[lx, ly]} ({self.locator.size} m) is not on the stand's "
                           f"front ({self.stand[0]} m wide, {stand_h:.3f} m tall, below the box)")
        return out

    def marker_ids(self) -> tuple[int, ...]:
        """Every marker id on the panel (face markers and the locator)."""
        return tuple(m.id for m in self.markers) + ((self.locator.id,) if self.locator else ())


def panel_transform(x: float, y: float, yaw: float, height: float) -> np.ndarray:
    """``T_map_panel`` (4x4) of a face centre at (x, y, height) [m] looking along ``yaw``
    [rad]: z = (cos yaw, sin yaw, 0) out of the face, y up, x = y cross z (right as seen
    from the front)."""
    c, s = math.cos(yaw), math.sin(yaw)
    T = np.eye(4)
    T[:3, 0] = (-s, c, 0.0)
    T[:3, 1] = (0.0, 0.0, 1.0)
    T[:3, 2] = (c, s, 0.0)
    T[:3, 3] = (x, y, height)
    return T


def panel_boxes(panel: Panel, T_map_panel: np.ndarray) -> list[tuple[str, np.ndarray, tuple[float, float, float]]]:
    """The panel's static parts ``(name, T_map_box centre, size)``, z up (local x along the
    face normal, y along the face, as a shelf's): the box and the stand under it."""
    w, h, d = panel.size
    sw, sd = panel.stand
    yaw = math.atan2(float(T_map_panel[1, 2]), float(T_map_panel[0, 2]))
    c = T_map_panel[:3, 3]
    n = T_map_panel[:3, 2]
    stand_h = panel.height - h / 2
    box_c = c - n * d / 2
    stand_c = c - n * sd / 2
    return [(f"{panel.name}_box", planar_transform(box_c[0], box_c[1], yaw, panel.height), (d, w, h)),
            (f"{panel.name}_stand", planar_transform(stand_c[0], stand_c[1], yaw, stand_h / 2), (sd, sw, stand_h))]


@dataclass
class Press:
    """One press of a cap (ground truth): clock times ``start`` / ``end`` [s], the deepest
    travel ``depth`` [m], whether it passed the switch point (``switched``), and the press
    point's ``offset`` [m] from the button's centre in the face plane at the deepest
    travel (None: no robot link was touching then)."""

    panel: str
    button: str
    start: float
    end: float = math.nan
    depth: float = 0.0
    switched: bool = False
    offset: float | None = None
    offset_xy: tuple[float, float] | None = None

    def record(self) -> dict[str, Any]:
        """The ``panel_press`` truth record (m, s; offsets also in mm)."""
        return {"panel": self.panel, "button": self.button, "t": round(self.start, 4), "end": round(self.end, 4),
                "depth_mm": round(self.depth * 1e3, 2), "switched": self.switched,
                "offset_mm": None if self.offset is None else round(self.offset * 1e3, 2),
                "offset_xy_mm": None if self.offset_xy is None else [round(v * 1e3, 2) for v in self.offset_xy]}


@dataclass
class _Cap:
    panel: Panel
    button: PanelButton
    body: int
    link: int
    light_link: int
    light: bool = False
    press: Press | None = None


@dataclass
class SimPanels:
    """The spawned panels of a world in pybullet client ``cid``: one multibody per panel
    (base at the panel frame, a prismatic link per cap, a visual link per light and per
    marker). :meth:`step` after each physics step; :meth:`at_rest` tells the backend
    whether physics may pause; :meth:`lights`, :attr:`presses` and :meth:`drain` are
    ground truth."""

    cid: int
    poses: Mapping[str, np.ndarray]
    caps: list[_Cap] = field(default_factory=list)
    bodies: dict[str, int] = field(default_factory=dict)
    presses: list[Press] = field(default_factory=list)
    _drained: int = 0

    @classmethod
    def spawn(cls, panels: Sequence[Panel], poses: Mapping[str, np.ndarray], cid: int, *,
              texture_path: Any, group: int, mask: int) -> SimPanels:
        """Create each panel's caps, lights and markers in ``cid`` (the box and stand are
        static parts spawned with the world). ``texture_path(id)`` gives a marker's PNG;
        ``group`` / ``mask``: the caps' collision filter."""
        out = cls(cid, dict(poses))
        for panel in panels:
            out._spawn_one(panel, poses[panel.name], texture_path, group, mask)
        return out

    def _spawn_one(self, panel: Panel, T: np.ndarray, texture_path: Any, group: int, mask: int) -> None:
        import pybullet as p  # here: the world schema loads without the engine (mapgen, validate)
        cid = self.cid
        masses, cols, viss, poss, axes, types, textures = [], [], [], [], [], [], []
        caps: list[tuple[PanelButton, int, int]] = []
        for b in panel.buttons:
            r, length = b.diameter / 2, b.cap_height + b.stroke
            # link origin at the cap's top centre; the cylinder reaches into the box
            cols.append(p.createCollisionShape(p.GEOM_CYLINDER, radius=r, height=length,
                                               collisionFramePosition=[0, 0, -length / 2], physicsClientId=cid))
            viss.append(p.createVisualShape(p.GEOM_CYLINDER, radius=r, length=length, visualFramePosition=[0, 0, -length / 2],
                                            rgbaColor=[*b.color, 1.0], physicsClientId=cid))
            masses.append(0.01)
            poss.append([b.position[0], b.position[1], b.cap_height])
            axes.append([0, 0, -1])
            types.append(p.JOINT_PRISMATIC)
            textures.append(None)
            lr = b.light_diameter / 2
            cols.append(-1)
            viss.append(p.createVisualShape(p.GEOM_CYLINDER, radius=lr, length=0.004, rgbaColor=list(LIGHT_OFF),
                                            physicsClientId=cid))
            masses.append(0.0)
            poss.append([b.light[0], b.light[1], 0.002])
            axes.append([0, 0, 1])
            types.append(p.JOINT_FIXED)
            textures.append(None)
            caps.append((b, len(masses) - 2, len(masses) - 1))
        quads = [(m.id, m.position, panel.marker_size) for m in panel.markers]
        if panel.locator is not None:
            quads.append((panel.locator.id, panel.locator.position, panel.locator.size))
        for mid, (x, y), size in quads:
            s = size * 8 / 6 / 2
            cols.append(-1)
            viss.append(p.createVisualShape(p.GEOM_MESH, vertices=[[-s, -s, 0], [s, -s, 0], [s, s, 0], [-s, s, 0]],
                                            indices=[0, 1, 2, 0, 2, 3], uvs=[[0, 0], [1, 0], [1, 1], [0, 1]],
                                            normals=[[0, 0, 1]] * 4, physicsClientId=cid))
            masses.append(0.0)
            poss.append([x, y, 0.0006])
            axes.append([0, 0, 1])
            types.append(p.JOINT_FIXED)
            textures.append(mid)
        n = len(masses)
        pos, quat = position_quat(T)
        body = p.createMultiBody(
            baseMass=0, baseCollisionShapeIndex=-1, baseVisualShapeIndex=-1, basePosition=pos, baseOrientation=quat,
            linkMasses=masses, linkCollisionShapeIndices=cols, linkVisualShapeIndices=viss, linkPositions=poss,
            linkOrientations=[[0, 0, 0, 1]] * n, linkInertialFramePositions=[[0, 0, 0]] * n,
            linkInertialFrameOrientations=[[0, 0, 0, 1]] * n, linkParentIndices=[0] * n, linkJointTypes=types,
            linkJointAxis=axes, physicsClientId=cid)
        for link, mid in enumerate(textures):
            if mid is not None:
                tex = p.loadTexture(str(texture_path(mid)), physicsClientId=cid)
                p.changeVisualShape(body, link, textureUniqueId=tex, rgbaColor=[1, 1, 1, 1], physicsClientId=cid)
        for li in range(-1, n):
            p.setCollisionFilterGroupMask(body, li, group, mask, physicsClientId=cid)
        for b, link, light in caps:
            p.changeDynamics(body, link, jointLowerLimit=0.0, jointUpperLimit=b.stroke, lateralFriction=0.8,
                             linearDamping=0.0, jointDamping=0.5, physicsClientId=cid)
            # the return spring: a motor holding the cap out with at most `force` newtons
            p.setJointMotorControl2(body, link, p.POSITION_CONTROL, targetPosition=0.0, force=b.force,
                                    physicsClientId=cid)
            self.caps.append(_Cap(panel, b, body, link, light))
        self.bodies[panel.name] = body

    # ------------------------------------------------------------------ stepping

    def step(self, now: float) -> None:
        """After a physics step at clock time ``now`` [s]: latch lights, follow presses."""
        import pybullet as p  # here: the world schema loads without the engine (mapgen, validate)
        for cap in self.caps:
            q = float(p.getJointState(cap.body, cap.link, physicsClientId=self.cid)[0])
            b = cap.button
            if q > TOUCH_DEPTH:
                if cap.press is None:
                    cap.press = Press(cap.panel.name, b.name, now)
                pr = cap.press
                if q > pr.depth:
                    pr.depth = q
                    where = self._press_point(cap)
                    if where is not None:
                        dx, dy = where[0] - b.position[0], where[1] - b.position[1]
                        pr.offset_xy, pr.offset = (dx, dy), math.hypot(dx, dy)
                if q >= PRESS_FRACTION * b.travel:
                    pr.switched = True
                    if not cap.light:
                        cap.light = True
                        p.changeVisualShape(cap.body, cap.light_link, rgbaColor=list(LIGHT_ON), physicsClientId=self.cid)
                        log.debug("panel %s: button %s switched at %.3f s (%.1f mm)", cap.panel.name, b.name, now, q * 1e3)
            elif cap.press is not None:
                cap.press.end = now
                self.presses.append(cap.press)
                cap.press = None

    def _press_point(self, cap: _Cap) -> tuple[float, float] | None:
        """Centre [x, y] in the panel frame of the bounding boxes of the other bodies' links
        touching the cap, or None."""
        import pybullet as p  # here: the world schema loads without the engine (mapgen, validate)
        touching = {(c[2], c[4]) for c in p.getContactPoints(bodyA=cap.body, linkIndexA=cap.link, physicsClientId=self.cid)}
        if not touching:
            return None
        lo = np.full(3, np.inf)
        hi = np.full(3, -np.inf)
        for body, link in touching:
            a, b = p.getAABB(body, link, physicsClientId=self.cid)
            lo, hi = np.minimum(lo, a), np.maximum(hi, b)
        centre = (lo + hi) / 2
        T = self.poses[cap.panel.name]
        local = T[:3, :3].T @ (centre - T[:3, 3])
        return float(local[0]), float(local[1])

    def at_rest(self) -> bool:
        """Every cap out (physics may pause without freezing a cap half-way back)."""
        return all(c.press is None for c in self.caps)

    # ------------------------------------------------------------------ ground truth

    def lights(self) -> dict[str, bool]:
        """``{"panel/button": light on}``."""
        return {f"{c.panel.name}/{c.button.name}": c.light for c in self.caps}

    def drain(self) -> list[Press]:
        """The presses finished since the last call."""
        out = self.presses[self._drained:]
        self._drained = len(self.presses)
        return out

    def hide_markers(self, panel: str) -> None:
        """Sim-only fault/test helper: the panel's face markers stop being visible (the
        locator stays)."""
        import pybullet as p  # here: the world schema loads without the engine (mapgen, validate)
        cap = next((c for c in self.caps if c.panel.name == panel), None)
        if cap is None:
            raise KeyError(f"no panel {panel!r}")
        first = 2 * len(cap.panel.buttons)  # links: cap and light per button, then the markers
        for k in range(len(cap.panel.markers)):
            p.changeVisualShape(cap.body, first + k, rgbaColor=[0, 0, 0, 0], physicsClientId=self.cid)

    def remove_button(self, panel: str, button: str) -> None:
        """Sim-only fault/test helper: take a button's cap off (it can no longer be pressed)."""
        import pybullet as p  # here: the world schema loads without the engine (mapgen, validate)
        for c in self.caps:
            if c.panel.name == panel and c.button.name == button:
                p.changeVisualShape(c.body, c.link, rgbaColor=[0, 0, 0, 0], physicsClientId=self.cid)
                p.setCollisionFilterGroupMask(c.body, c.link, 0, 0, physicsClientId=self.cid)
                return
        raise KeyError(f"no button {button!r} on panel {panel!r}")

