"""Path tracking for a differential-drive base: pure pursuit with a final heading alignment.

:class:`PathTracker` is stateful and advanced one control tick at a time:
``v, w, done = tracker.step(pose, v_meas, w_meas, dt)``. It never blocks and never
reads a clock; the caller passes the tick period ``dt`` [s].

Phases: ``turn`` (rotate in place while the path direction is far behind the heading),
``track`` (pure pursuit: curvature ``2 sin(alpha) / L`` towards a look-ahead point, speed
reduced in tight turns and so the base can stop at the goal with ``accel_v``), ``align``
(rotate in place to the goal heading, when one is given), ``done``. Every command
respects ``max_v``/``max_w`` and changes by at most ``accel * dt`` per tick.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

from mmexec.drivers.geometry import wrap_angle
from mmexec.drivers.interfaces import Pose2D

__all__ = ["PathTracker", "TrackerConfig"]


@dataclass(frozen=True)
class TrackerConfig:
    """Tracker tuning. Speeds in m/s and rad/s, accelerations in m/s^2 and rad/s^2,
    distances in m, angles in rad."""

    max_v: float = 0.5
    max_w: float = 1.5
    accel_v: float = 0.8
    accel_w: float = 3.0
    lookahead: float = 0.35
    goal_tolerance: float = 0.05
    heading_tolerance: float = 0.05
    turn_in_place_angle: float = 1.0   # rad: rotate on the spot when the path is further off
    min_v: float = 0.03                 # m/s: creep speed near the goal so it is reached

    def validate(self) -> list[str]:
        errs = []
        for name in ("max_v", "max_w", "accel_v", "accel_w", "lookahead", "goal_tolerance", "heading_tolerance"):
            if not getattr(self, name) > 0:
                errs.append(f"{name}: must be > 0, got {getattr(self, name)}")
        return errs


def _toward(current: float, target: float, max_delta: float) -> float:
    if target > current + max_delta:
        return current + max_delta
    if target < current - max_delta:
        return current - max_delta
    return target


class PathTracker:
    """Track a polyline ``path`` of map points [m], then turn to ``goal_heading`` [rad]
    (None: keep the arrival heading)."""

    def __init__(
        self,
        path: list[tuple[float, float]],
        config: TrackerConfig | None = None,
        goal_heading: float | None = None,
    ) -> None:
        if not path:
            raise ValueError("PathTracker: empty path")
        self.config = config or TrackerConfig()
        errs = self.config.validate()
        if errs:
            raise ValueError("TrackerConfig: " + "; ".join(errs))
        self.path = [(float(x), float(y)) for x, y in path]
        self.goal_heading = goal_heading
        self.phase = "turn" if len(self.path) > 1 else "track"
        self._seg = 0
        self._v: float | None = None
        self._w: float | None = None

    # ------------------------------------------------------------------ geometry
    @property
    def goal(self) -> tuple[float, float]:
        return self.path[-1]

    def _project(self, px: float, py: float) -> tuple[int, float]:
        """Closest point on the path from the current segment onward (progress never goes
        back): returns (segment index, parameter in [0, 1])."""
        best = (self._seg, 0.0)
        best_d = math.inf
        for i in range(self._seg, max(self._seg + 1, len(self.path) - 1)):
            if i + 1 >= len(self.path):
                ax, ay = self.path[-1]
                d = math.hypot(px - ax, py - ay)
                if d < best_d:
                    best, best_d = (i, 0.0), d
                break
            ax, ay = self.path[i]
            bx, by = self.path[i + 1]
            dx, dy = bx - ax, by - ay
            L2 = dx * dx + dy * dy
            t = 0.0 if L2 == 0 else max(0.0, min(1.0, ((px - ax) * dx + (py - ay) * dy) / L2))
            d = math.hypot(px - (ax + t * dx), py - (ay + t * dy))
            if d < best_d - 1e-12:
                best, best_d = (i, t), d
            if d > best_d + 2 * self.config.lookahead:
                break
        return best

    def _lookahead_point(self, px: float, py: float) -> tuple[float, float]:
        seg, t = self._project(px, py)
        self._seg = seg
        if len(self.path) == 1:
            return self.path[0]
        ax, ay = self.path[seg]
        bx, by = self.path[min(seg + 1, len(self.path) - 1)]
        cx, cy = ax + t * (bx - ax), ay + t * (by - ay)
        remaining = self.config.lookahead
        # walk along the path from the projection
        pts = [(cx, cy)] + self.path[seg + 1 :]
        for (x0, y0), (x1, y1) in itertools.pairwise(pts):
            L = math.hypot(x1 - x0, y1 - y0)
            if L >= remaining:
                a = remaining / L if L > 0 else 0.0
                return x0 + a * (x1 - x0), y0 + a * (y1 - y0)
            remaining -= L
        return self.path[-1]

    def remaining_distance(self, px: float, py: float) -> float:
        """Path length [m] left from the projection of ``(px, py)`` to the goal."""
        seg, t = self._project(px, py)
        if len(self.path) == 1:
            return math.hypot(self.path[0][0] - px, self.path[0][1] - py)
        ax, ay = self.path[seg]
        bx, by = self.path[min(seg + 1, len(self.path) - 1)]
        rest = (1.0 - t) * math.hypot(bx - ax, by - ay)
        for (x0, y0), (x1, y1) in zip(self.path[seg + 1 :], self.path[seg + 2 :]):
            rest += math.hypot(x1 - x0, y1 - y0)
        return rest

    # ------------------------------------------------------------------ control
    def reset(self) -> None:
        """Forget the last command (next step starts from the measured velocities)."""
        self._v = self._w = None

    def step(self, pose: Pose2D, v_meas: float, w_meas: float, dt: float) -> tuple[float, float, bool]:
        """One control tick: base ``pose`` in ``map``, measured ``v_meas`` [m/s] and
        ``w_meas`` [rad/s], tick period ``dt`` [s] > 0. Returns the command ``(v, w)`` and
        ``done`` (True once the goal position and heading are reached; the command is then
        zero)."""
        if not dt > 0:
            raise ValueError(f"PathTracker.step: dt must be > 0, got {dt}")
        cfg = self.config
        v0 = v_meas if self._v is None else self._v
        w0 = w_meas if self._w is None else self._w
        gx, gy = self.goal
        dist_goal = math.hypot(gx - pose.x, gy - pose.y)
        v_des, w_des = 0.0, 0.0

        if self.phase in ("turn", "track") and dist_goal <= cfg.goal_tolerance:
            self.phase = "align" if self.goal_heading is not None else "done"

        if self.phase == "turn":
            lx, ly = self._lookahead_point(pose.x, pose.y)
            err = wrap_angle(math.atan2(ly - pose.y, lx - pose.x) - pose.theta)
            if abs(err) < cfg.turn_in_place_angle * 0.5:
                self.phase = "track"
            else:
                w_des = self._turn_rate(err, cfg)
        if self.phase == "track":
            lx, ly = self._lookahead_point(pose.x, pose.y)
            dx, dy = lx - pose.x, ly - pose.y
            Ld = max(math.hypot(dx, dy), 1e-6)
            alpha = wrap_angle(math.atan2(dy, dx) - pose.theta)
            if abs(alpha) > cfg.turn_in_place_angle:
                self.phase = "turn"
                w_des = self._turn_rate(alpha, cfg)
            else:
                curvature = 2.0 * math.sin(alpha) / Ld
                remaining = self.remaining_distance(pose.x, pose.y)
                v_stop = math.sqrt(2.0 * cfg.accel_v * max(0.0, remaining - 0.5 * cfg.goal_tolerance))
                v_des = min(cfg.max_v * max(0.0, math.cos(alpha)), v_stop)
                v_des = max(v_des, min(cfg.min_v, cfg.max_v))
                if abs(curvature) * v_des > cfg.max_w:
                    v_des = cfg.max_w / abs(curvature)
                w_des = curvature * v_des
        if self.phase == "align":
            assert self.goal_heading is not None
            err = wrap_angle(self.goal_heading - pose.theta)
            if abs(err) <= cfg.heading_tolerance:
                self.phase = "done"
            else:
                w_des = self._turn_rate(err, cfg)
        if self.phase == "done":
            v_des = w_des = 0.0

        v = _toward(v0, v_des, cfg.accel_v * dt)
        w = _toward(w0, w_des, cfg.accel_w * dt)
        v = max(-cfg.max_v, min(cfg.max_v, v))
        w = max(-cfg.max_w, min(cfg.max_w, w))
        self._v, self._w = v, w
        done = self.phase == "done" and abs(v) < 1e-9 and abs(w) < 1e-9
        return v, w, done

    @staticmethod
    def _turn_rate(err: float, cfg: TrackerConfig) -> float:
        """Yaw rate [rad/s] that can still stop at ``err`` [rad] with ``accel_w``."""
        w_stop = math.sqrt(2.0 * cfg.accel_w * max(0.0, abs(err) - 0.5 * cfg.heading_tolerance))
        mag = min(cfg.max_w, w_stop, max(0.15, 2.5 * abs(err)))
        return math.copysign(mag, err)
