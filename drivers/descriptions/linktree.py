"""A robot's link tree as data: links with primitive geometry and the joints between them.

This is what a description's URDF hook returns (:attr:`RobotDescription.urdf_tree
<mmexec.drivers.descriptions.description.RobotDescription.urdf_tree>`); the URDF writer
(:mod:`mmexec.sim.models.urdfgen`) turns it into XML. Geometry is primitive only (boxes,
cylinders, spheres) so collision checks stay cheap; the geometries marked ``collide``
are the collision model the simulator and the planning scene use. Lengths are metres,
angles radians, masses kilograms; every ``xyz``/``rpy`` places a child in its parent's
frame (URDF convention: roll, pitch, yaw about fixed x, y, z).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

__all__ = ["BLUE", "DARK", "GREY", "LIGHT", "X_AXIS", "Y_AXIS", "Z_AXIS", "Geom", "Joint", "Link", "LinkTree", "Vec3"]

Vec3 = tuple[float, float, float]

#: visual colours (rgba) shared by the models
DARK = (0.15, 0.15, 0.15, 1.0)
GREY = (0.55, 0.55, 0.58, 1.0)
BLUE = (0.2, 0.3, 0.7, 1.0)
LIGHT = (0.8, 0.8, 0.82, 1.0)
#: joint axes
X_AXIS = (1.0, 0.0, 0.0)
Y_AXIS = (0.0, 1.0, 0.0)
Z_AXIS = (0.0, 0.0, 1.0)


@dataclass(frozen=True)
class Geom:
    """A primitive: ``box`` (size = full extents [m]), ``cylinder`` (radius, length along
    z [m]), ``sphere`` (radius [m]). ``xyz`` [m] / ``rpy`` [rad] place it in its link
    frame; ``collide`` False makes it visual only."""

    kind: Literal["box", "cylinder", "sphere"]
    size: tuple[float, ...]
    xyz: Vec3 = (0.0, 0.0, 0.0)
    rpy: Vec3 = (0.0, 0.0, 0.0)
    rgba: tuple[float, float, float, float] = (0.6, 0.6, 0.6, 1.0)
    collide: bool = True

    def volume(self) -> float:
        """Volume [m^3]."""
        if self.kind == "box":
            return self.size[0] * self.size[1] * self.size[2]
        if self.kind == "cylinder":
            return math.pi * self.size[0] ** 2 * self.size[1]
        return 4.0 / 3.0 * math.pi * self.size[0] ** 3


@dataclass(frozen=True)
class Link:
    """A link with primitive geometry and a mass [kg] whose centre ``com`` [m] is in the
    link frame (the writer derives the inertia from a box bounding the geometry)."""

    name: str
    geoms: tuple[Geom, ...] = ()
    mass: float = 0.05
    com: Vec3 = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class Joint:
    """``fixed``, ``revolute``, ``continuous`` or ``prismatic`` joint: the ``child`` link's
    frame at ``xyz`` [m] / ``rpy`` [rad] in ``parent``'s, moving along/about ``axis``
    (child frame); limits in rad or m, velocity in rad/s or m/s, effort in N m or N."""

    name: str
    kind: Literal["fixed", "revolute", "continuous", "prismatic"]
    parent: str
    child: str
    xyz: Vec3 = (0.0, 0.0, 0.0)
    rpy: Vec3 = (0.0, 0.0, 0.0)
    axis: Vec3 = (0.0, 0.0, 1.0)
    lower: float = 0.0
    upper: float = 0.0
    velocity: float = 0.0
    effort: float = 0.0


@dataclass
class LinkTree:
    """A robot's links and joints in the order they are written; :meth:`link` and
    :meth:`joint` append one (the :class:`Link` / :class:`Joint` arguments)."""

    name: str
    links: list[Link] = field(default_factory=list)
    joints: list[Joint] = field(default_factory=list)

    def link(self, *a: object, **k: object) -> None:
        """Append ``Link(*a, **k)``."""
        self.links.append(Link(*a, **k))  # type: ignore[arg-type]

    def joint(self, *a: object, **k: object) -> None:
        """Append ``Joint(*a, **k)``."""
        self.joints.append(Joint(*a, **k))  # type: ignore[arg-type]
