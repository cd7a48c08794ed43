"""People in the simulation: kinematic cylinders walking waypoint loops.

Each :class:`~mmexec.sim.world.Person` of a world (its ``people:`` section, or drawn by
the ``crowd`` fault, :func:`mmexec.sim.faults.crowd_people`) becomes a massless pybullet
cylinder that the lidar and the camera see and the base's bumper feels
(:class:`mmexec.sim.capabilities.SimBase`). :meth:`SimPeople.step` moves them every
physics substep, as the base is moved: no physics acts on them. They push items (a body
of infinite mass) but pass through the arm: a person moved into a holding arm would
throw its joints about, which no real person does; an arm touching a person is found by
the ground truth instead (:mod:`mmexec.sim.truth`).

A person's walk, per substep of ``dt`` seconds:

1. ``trigger`` (optional): stand at the first waypoint until the robot's true position is
   within ``trigger`` metres;
2. ``delay``: stand there ``delay`` more seconds;
3. walk the closed loop of waypoints at ``speed``, standing ``pause`` seconds at each
   waypoint reached.

People are polite: a person stands still for the substep when the step would bring them
closer than :data:`YIELD_GAP` to the robot's footprint circle (and closer than they are),
so they never walk into the robot; a contact with a person is the robot's doing. A
person kept waiting for :data:`PATIENCE` seconds turns round and walks their loop the
other way (someone the robot waits for, and who waits for the robot, would otherwise
stand there for ever). A person who turned round and is blocked again before getting
:data:`CORNER_GAP` further from the robot (cornered: the robot stands where both ways
of their loop pass it, by a waypoint) walks round the robot instead: each substep a
step along the tangent of the circle round the robot's centre (the side nearer where
they were going; never closer to the robot, and only where the static geometry leaves
their radius + :data:`ROUND_CLEAR`, when the caller gives the clearance), then straight
on towards the end of the leg they are on, where the loop resumes. Before, such a person stood by the robot for minutes: in the
LoCoBot crowd campaigns a person stood by home or a viewpoint for the rest of the trial
and the robot, which could not reach its goal past them, timed out (3 of 200 trials).
People do not avoid each other (they may overlap; neither the lidar nor the robot minds).

Frames: ``map``; metres, seconds. Sim-only; skills never see this module.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import pybullet as p

from mmexec.sim.scene import GROUP_ITEM, GROUP_QUERY, GROUP_STATIC
from mmexec.sim.world import Person

__all__ = ["CORNER_GAP", "PATIENCE", "ROUND_CLEAR", "YIELD_GAP", "SimPeople", "Walk"]

#: [m] the smallest gap a person leaves between themselves and the robot's footprint circle
#: (more than the robot's own safety margin, so a person who waits is never inside it)
YIELD_GAP = 0.3
#: [s] how long a person waits for the robot before turning round
PATIENCE = 3.0
#: [m] room a person walking round the robot keeps from the static geometry beyond their radius
ROUND_CLEAR = 0.05
#: [m] a person who turned round for the robot and is blocked again before their gap to
#: it grew beyond YIELD_GAP + this is cornered, and walks round it (a person stepping a
#: few cm each way between two legs that both pass the robot stood by it for minutes)
CORNER_GAP = 0.5
#: RGBA of a person's body (a dark blue coat: a distinct colour in camera frames)
_COLOUR = (0.15, 0.2, 0.45, 1.0)


@dataclass
class Walk:
    """Where one person is in their walk: ``phase`` (``trigger``, ``delay``, ``walk`` or
    ``pause``), the leg (from waypoint ``leg`` to the next), ``along`` [m] on it from
    waypoint ``leg``, the seconds left of the delay or pause (``timer``), the position
    ``xy`` [m] in ``map``, the ``direction`` along the loop (+1 as given, -1 reversed),
    how long they have been ``waiting`` for the robot [s], whether they ``turned`` round
    for it and have not got :data:`CORNER_GAP` further from it since, and whether they are ``rounding`` it (off their
    leg, walking round the robot and then straight to the leg's end)."""

    phase: str
    leg: int
    along: float
    timer: float
    xy: tuple[float, float]
    direction: int = 1
    waiting: float = 0.0
    turned: bool = False
    rounding: bool = False
    side: float = 0.0


class SimPeople:
    """The people of one simulated world, moved kinematically (see the module docstring).

    ``people`` as loaded (:attr:`mmexec.sim.world.World.people`); ``cid`` the pybullet
    client. Bodies are created here, one per person, standing at their first waypoint."""

    def __init__(self, people: Sequence[Person], cid: int) -> None:
        self.people = tuple(people)
        self._cid = cid
        self.names = tuple(pe.name for pe in self.people)
        self.radii = np.array([pe.radius for pe in self.people], dtype=float)
        self._legs = [self._leg_table(pe) for pe in self.people]
        self.walks = [Walk("trigger" if pe.trigger is not None else "delay" if pe.delay > 0 else "walk", 0, 0.0,
                           pe.delay, pe.waypoints[0]) for pe in self.people]
        self.bodies: list[int] = []
        for pe in self.people:
            col = p.createCollisionShape(p.GEOM_CYLINDER, radius=pe.radius, height=pe.height, physicsClientId=cid)
            vis = p.createVisualShape(p.GEOM_CYLINDER, radius=pe.radius, length=pe.height, rgbaColor=_COLOUR,
                                      physicsClientId=cid)
            x, y = pe.waypoints[0]
            body = p.createMultiBody(0.0, col, vis, [x, y, pe.height / 2], physicsClientId=cid)
            p.setCollisionFilterGroupMask(body, -1, GROUP_STATIC, GROUP_QUERY | GROUP_ITEM, physicsClientId=cid)
            self.bodies.append(body)
        self._placed = [w.xy for w in self.walks]

    def __len__(self) -> int:
        return len(self.people)

    @staticmethod
    def _leg_table(pe: Person) -> list[tuple[tuple[float, float], tuple[float, float], float]]:
        """``(from, to, length [m])`` of each leg of the closed loop."""
        pts = list(pe.waypoints)
        return [(a, b, math.hypot(b[0] - a[0], b[1] - a[1])) for a, b in zip(pts, pts[1:] + pts[:1])]

    def positions(self) -> np.ndarray:
        """Centres (k, 2) [m] in ``map``."""
        return np.array([w.xy for w in self.walks], dtype=float).reshape(-1, 2)

    def gaps(self, x: float, y: float, radius: float) -> np.ndarray:
        """Gap [m] (k,) between a circle of ``radius`` at ``(x, y)`` and each person
        (centre distance minus both radii; negative: they overlap)."""
        c = self.positions()
        return np.hypot(c[:, 0] - x, c[:, 1] - y) - self.radii - radius

    def step(self, dt: float, robot_xy: tuple[float, float], robot_radius: float,
             clear: Callable[[float, float, float], bool] | None = None) -> None:
        """Advance every person by ``dt`` [s] of clock time, the robot's true centre at
        ``robot_xy`` [m] with a footprint of ``robot_radius`` [m], and put the bodies
        there. ``clear(x, y, r)``: whether a disk of radius ``r`` [m] at ``(x, y)`` is
        clear of the static geometry (:meth:`mmexec.sim.clearance.ClearanceMap.clear`),
        for a person walking round the robot (None: anywhere)."""
        for i, pe in enumerate(self.people):
            w = self.walks[i]
            if w.phase == "trigger":
                assert pe.trigger is not None
                if math.hypot(w.xy[0] - robot_xy[0], w.xy[1] - robot_xy[1]) <= pe.trigger:
                    w.phase = "delay" if pe.delay > 0 else "walk"
                continue
            if w.phase in ("delay", "pause"):
                w.timer -= dt
                if w.timer <= 0.0:
                    w.phase, w.timer = "walk", 0.0
                continue
            self._walk(i, pe, w, dt, robot_xy, robot_radius, clear)
        for i, w in enumerate(self.walks):
            if w.xy != self._placed[i]:
                pe = self.people[i]
                p.resetBasePositionAndOrientation(self.bodies[i], [w.xy[0], w.xy[1], pe.height / 2], [0, 0, 0, 1],
                                                  physicsClientId=self._cid)
                self._placed[i] = w.xy

    def _walk(self, i: int, pe: Person, w: Walk, dt: float, robot_xy: tuple[float, float],
              robot_radius: float, clear: Callable[[float, float, float], bool] | None) -> None:
        """One substep of walking for person ``i`` (the rules of the module docstring)."""
        legs = self._legs[i]
        leg = w.leg
        arrived = False
        if w.rounding:  # off the leg: straight on to its end in the walking direction
            tx, ty = legs[leg][1] if w.direction > 0 else legs[leg][0]
            d = math.hypot(tx - w.xy[0], ty - w.xy[1])
            step = pe.speed * dt
            arrived = d <= step
            xy = (tx, ty) if arrived else (w.xy[0] + step * (tx - w.xy[0]) / d, w.xy[1] + step * (ty - w.xy[1]) / d)
            along = w.along
            if arrived and w.direction > 0:
                leg, along = (leg + 1) % len(legs), 0.0
            elif arrived:
                leg = (leg - 1) % len(legs)
                along = legs[leg][2]
        else:
            along = w.along + w.direction * pe.speed * dt
            arrived = along >= legs[leg][2] - 1e-9 if w.direction > 0 else along <= 1e-9
            if arrived and w.direction > 0:
                leg, along = (leg + 1) % len(legs), 0.0
                xy = legs[leg][0]
            elif arrived:  # reversed: at waypoint ``leg``, next down the previous leg from its end
                xy = legs[leg][0]
                leg = (leg - 1) % len(legs)
                along = legs[leg][2]
            else:
                (ax, ay), (bx, by), length = legs[leg]
                f = along / length
                xy = (ax + f * (bx - ax), ay + f * (by - ay))
        rx, ry = robot_xy
        gap_new = math.hypot(xy[0] - rx, xy[1] - ry) - pe.radius - robot_radius
        if gap_new < YIELD_GAP:
            gap_now = math.hypot(w.xy[0] - rx, w.xy[1] - ry) - pe.radius - robot_radius
            if gap_new < gap_now:  # the robot is in the way
                if w.turned or w.rounding:
                    q = self._round_step(pe, w, xy, robot_xy, pe.speed * dt, clear, gap_now < YIELD_GAP)
                    if q is not None:  # cornered: walk round it
                        w.xy, w.rounding, w.turned, w.waiting = q, True, False, 0.0
                        return
                w.waiting += dt  # stand aside
                if w.waiting >= PATIENCE:
                    w.direction, w.waiting, w.turned = -w.direction, 0.0, True
                return
        if gap_new >= YIELD_GAP + CORNER_GAP:
            w.turned = False
        if arrived:
            w.rounding, w.side = False, 0.0
        w.xy, w.leg, w.along, w.waiting = xy, leg, along, 0.0
        if arrived and pe.pause > 0:
            w.phase, w.timer = "pause", pe.pause

    @staticmethod
    def _round_step(pe: Person, w: Walk, towards: tuple[float, float], robot_xy: tuple[float, float], step: float,
                    clear: Callable[[float, float, float], bool] | None, near: bool) -> tuple[float, float] | None:
        """Where person ``pe`` at ``w.xy``, who wanted to step to ``towards`` [m], steps
        instead to walk round the robot centred at ``robot_xy``: ``step`` [m] along the
        tangent of the circle round it (which never comes closer to the robot; ``near``,
        closer than :data:`YIELD_GAP` to its footprint, where the robot came up to them:
        half outwards, so they pass round it no nearer than that, clear of an item it holds
        out), on the side ``w.side`` kept from the first such step (at first the side
        nearer ``towards``), or the other where ``clear`` does not leave the person's
        radius + :data:`ROUND_CLEAR` (the side then kept); None when neither does."""
        here = w.xy
        ux, uy = robot_xy[0] - here[0], robot_xy[1] - here[1]
        n = math.hypot(ux, uy)
        if n < 1e-9:
            return None
        tx, ty = uy / n, -ux / n  # anticlockwise round the robot
        if w.side == 0.0:
            w.side = 1.0 if tx * (towards[0] - here[0]) + ty * (towards[1] - here[1]) >= 0.0 else -1.0
        out = 1.0 if near else 0.0
        for s in (w.side, -w.side):
            dx, dy = s * tx - out * ux / n, s * ty - out * uy / n
            k = step / math.hypot(dx, dy)
            q = (here[0] + k * dx, here[1] + k * dy)
            if clear is None or clear(q[0], q[1], pe.radius + ROUND_CLEAR):
                w.side = s
                return q
        return None
