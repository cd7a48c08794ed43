"""Fault injection for the simulation, configured by the ``faults:`` section of ``sim:``.

Each fault exercises one recovery path of a mission (see docs/sim.md):

* ``arm_fail: always`` or ``arm_fail_attempts: [1, 3]``: the n-th arm goal (1-based,
  counting every :meth:`Arm.follow`) stops half-way and FAILS ("arm motion failed");
* ``nav_blocked: [box_3]``: a static obstacle fills the approach area in front of the
  named items (in the physics world *and* the prior map), so no path reaches them;
* ``marker_bias: {box_2: [0.02, 0.0]}``: that item's marker texture is printed shifted
  on its face by (lateral, up) metres, so the detected marker is off the true box;
* ``grasp_slip: {after: 1.0, items: [box_1]}``: a held item slips out of the gripper
  ``after`` seconds of holding (items empty = every item);
* ``camera_dropout`` / ``lidar_dropout``: ``{p: 0.2, intervals: [[10, 20]]}``: a frame or
  scan is None with probability ``p`` and always inside the clock-time intervals [s];
* ``reflector_dropout``: ``{intervals: [[20, 40]], p: 0.0, reflectors: [refl_sw]}``: the
  named laser reflectors (empty = all) are covered: the lidar sees them as ordinary
  surfaces (low intensity), per scan with probability ``p`` and always inside the
  intervals; the posts stay where they are;
* ``kidnap``: ``{at: 30.0, pose: [x, y, yaw]}``: once, at clock time ``at`` [s], the robot
  is lifted and put down at ``pose`` in ``map`` (omitted: a random pose clear of the
  static geometry, at least ``min_distance`` [m] from where it was); the odometry does
  not notice.

Randomness comes from the backend's seeded generator, so a seed reproduces the faults.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from mmexec.sim.world import Obstacle, World

__all__ = ["Dropout", "FaultConfig", "FaultInjector", "GraspSlip", "Kidnap", "ReflectorDropout", "blocking_obstacles"]


@dataclass(frozen=True)
class Dropout:
    """Sensor dropout: probability ``p`` per request, plus always-off ``intervals`` [s]."""

    p: float = 0.0
    intervals: tuple[tuple[float, float], ...] = ()

    def validate(self) -> list[str]:
        out = [] if 0.0 <= self.p <= 1.0 else [f"p must be in [0, 1], got {self.p}"]
        out += [f"interval [{a}, {b}] must have start <= end" for a, b in self.intervals if a > b]
        return out


@dataclass(frozen=True)
class ReflectorDropout(Dropout):
    """Covered laser reflectors: ``reflectors`` (names; empty = all) return as ordinary
    surfaces with probability ``p`` per scan and always inside ``intervals`` [s]."""

    reflectors: tuple[str, ...] = ()


@dataclass(frozen=True)
class Kidnap:
    """Teleport the robot once at clock time ``at`` [s] to ``pose`` ``(x [m], y [m], yaw
    [rad])`` in ``map``, or, when None, to a random pose clear of the static geometry and
    at least ``min_distance`` [m] away."""

    at: float
    pose: tuple[float, float, float] | None = None
    min_distance: float = 1.0

    def validate(self) -> list[str]:
        out = [] if self.at >= 0 else [f"at must be >= 0 s, got {self.at}"]
        return out + ([] if self.min_distance >= 0 else [f"min_distance must be >= 0 m, got {self.min_distance}"])


@dataclass(frozen=True)
class GraspSlip:
    """A held item slips out ``after`` seconds of holding; ``items`` limits which (empty = all)."""

    after: float = 1.0
    items: tuple[str, ...] = ()

    def validate(self) -> list[str]:
        return [] if self.after >= 0 else [f"after must be >= 0 s, got {self.after}"]


@dataclass(frozen=True)
class FaultConfig:
    """The ``sim.faults`` section (all faults off by default)."""

    arm_fail: Literal["never", "always"] = "never"
    arm_fail_attempts: tuple[int, ...] = ()
    nav_blocked: tuple[str, ...] = ()
    nav_blocked_depth: float = 1.0
    marker_bias: dict[str, tuple[float, float]] = field(default_factory=dict)
    grasp_slip: GraspSlip | None = None
    camera_dropout: Dropout = field(default_factory=Dropout)
    lidar_dropout: Dropout = field(default_factory=Dropout)
    reflector_dropout: ReflectorDropout = field(default_factory=ReflectorDropout)
    kidnap: Kidnap | None = None

    def validate(self) -> list[str]:
        out = [f"arm_fail_attempts: attempt numbers start at 1, got {a}" for a in self.arm_fail_attempts if a < 1]
        if self.nav_blocked_depth <= 0:
            out.append("nav_blocked_depth must be > 0 m")
        return out

    def item_names(self) -> list[tuple[str, str]]:
        """(key, item name) pairs this config refers to, for checking against the world."""
        refs = [("nav_blocked", n) for n in self.nav_blocked] + [("marker_bias", n) for n in self.marker_bias]
        if self.grasp_slip is not None:
            refs += [("grasp_slip.items", n) for n in self.grasp_slip.items]
        return refs


def blocking_obstacles(world: World, items: tuple[str, ...], depth: float = 1.0) -> tuple[Obstacle, ...]:
    """Obstacles that fill the floor in front of each named item: from 0.05 m in front of
    the item's face out to ``depth`` [m], 1.2 m wide, 0.3 m tall (under shelf boards
    reachable by the arm would be blocked too, so the base cannot stand anywhere near)."""
    out = []
    for name in items:
        T = world.item_poses[name]
        it = world.item(name)
        yaw = math.atan2(T[1, 0], T[0, 0])
        front = it.size[0] / 2 + 0.05
        # the box's face is inside the shelf: start past the shelf front
        for s in world.spec.shelves:
            if s.name == it.shelf:
                front = it.inset + it.size[0] / 2 + 0.05
        centre = front + depth / 2
        x = T[0, 3] + centre * math.cos(yaw)
        y = T[1, 3] + centre * math.sin(yaw)
        out.append(Obstacle(name=f"fault_block_{name}", pose=(x, y, yaw), size=(depth, 1.2, 0.3)))
    return tuple(out)


class FaultInjector:
    """Decides, deterministically from a seeded generator, when each fault fires."""

    def __init__(self, cfg: FaultConfig, rng: np.random.Generator) -> None:
        self.cfg = cfg
        self._rng = rng
        self.arm_attempts = 0
        self._kidnapped = False
        self.fired: list[tuple[float, str]] = []  #: (clock time, fault) log, for tests and campaigns

    def arm_attempt_fails(self, now: float) -> bool:
        """Count one arm goal and say whether it must fail."""
        self.arm_attempts += 1
        fail = self.cfg.arm_fail == "always" or self.arm_attempts in self.cfg.arm_fail_attempts
        if fail:
            self.fired.append((now, f"arm_fail attempt {self.arm_attempts}"))
        return fail

    def _dropped(self, d: Dropout, now: float, what: str) -> bool:
        if any(a <= now <= b for a, b in d.intervals) or (d.p > 0 and self._rng.random() < d.p):
            self.fired.append((now, what))
            return True
        return False

    def camera_dropped(self, now: float) -> bool:
        return self._dropped(self.cfg.camera_dropout, now, "camera_dropout")

    def lidar_dropped(self, now: float) -> bool:
        return self._dropped(self.cfg.lidar_dropout, now, "lidar_dropout")

    def reflectors_covered(self, now: float) -> frozenset[str] | None:
        """The reflectors covered for a scan at ``now`` [s] (an empty set: all of them), or
        None when none is."""
        d = self.cfg.reflector_dropout
        return frozenset(d.reflectors) if self._dropped(d, now, "reflector_dropout") else None

    def kidnap_pose(self, now: float, here: tuple[float, float], clear: Callable[[float, float], bool],
                    bounds: tuple[float, float, float, float]) -> tuple[float, float, float] | None:
        """Once the kidnap is due at ``now`` [s] (and only once): where to put the robot,
        ``(x, y, yaw)`` in ``map``. A random pose is drawn uniformly in ``bounds`` ``(x0,
        y0, x1, y1)`` [m] until ``clear(x, y)`` and it lies ``min_distance`` from ``here``."""
        k = self.cfg.kidnap
        if k is None or self._kidnapped or now < k.at:
            return None
        self._kidnapped = True
        pose = k.pose
        if pose is None:
            x0, y0, x1, y1 = bounds
            for _ in range(10000):
                x, y = float(self._rng.uniform(x0, x1)), float(self._rng.uniform(y0, y1))
                if math.hypot(x - here[0], y - here[1]) >= k.min_distance and clear(x, y):
                    pose = (x, y, float(self._rng.uniform(-math.pi, math.pi)))
                    break
            else:
                raise RuntimeError(f"kidnap: no clear pose {k.min_distance} m from {here} in 10000 draws")
        self.fired.append((now, f"kidnap to ({pose[0]:.3f}, {pose[1]:.3f}, {pose[2]:.3f})"))
        return pose

    def slip_after(self, item: str) -> float | None:
        """Seconds of holding after which ``item`` slips out, or None."""
        gs = self.cfg.grasp_slip
        if gs is None or (gs.items and item not in gs.items):
            return None
        return gs.after
