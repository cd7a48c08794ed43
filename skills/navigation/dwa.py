"""Dynamic Window Approach local planner following a global A* path.

Per control tick (:meth:`DwaPlanner.step`):

1. **Dynamic window**: velocities reachable from the current command ``(v0, w0)`` under
   the base's velocity and acceleration limits
   (:meth:`mmexec.skills.navigation.limits.BaseLimits.window`), the forward speed also
   capped by the caller (e.g. the social speed scale near people) and so the base can
   stop at the goal (``v <= sqrt(2 a d)`` over the remaining path length ``d``). Target
   velocities are sampled on an ``n_v x n_w`` grid over what is reachable within
   ``window_time`` (with ``w = 0`` exactly when inside); the command sent is the first
   tick of the chosen ramp, so it always lies in the window of the tick ``dt``. (With a
   window of one 50 ms tick a base at rest sees only rollouts of a few centimetres, and
   the clearance term can then keep it from ever starting.)
2. **Rollouts**: each rollout ramps from ``(v0, w0)`` to its target at the full
   accelerations, then holds it for the rest of ``horizon``; poses at every ``step``, all
   rollouts and times in one array (:func:`rollouts`).
3. **Admissibility** (Fox et al.): a rollout that hits something (the costmap clearance
   under the robot radius, or a circle's safety radius with the circle moved at its
   tracked velocity) is kept only if the base can brake to a stop before the hit (the
   distance covered before it at least ``v^2 / (2 a)``). A start already inside an
   obstacle's zone does not condemn every rollout: a rollout collides only where it gets
   closer to that obstacle than at the start.
4. **Scoring** (lower is better; each term is dimensionless), with the rollout's end
   point projected on the path: ``path``: its distance to the path / ``path_scale``;
   ``heading``: the angle between its heading and the direction to the path point
   ``lookahead`` metres beyond its projection, / pi; ``goal``: minus the progress along
   the path (the projection's arc length gained) / (max_v * horizon); ``clearance``:
   ``1 - min(gap / scale, 1)`` with the smallest gap along the rollout, or ``3 - 2 t_hit /
   horizon`` for an admissible rollout that hits (it may still brake in time, but it
   heads for a collision); ``scale`` is ``clearance_scale``, or the smallest gap the path
   itself leaves over the stretch the rollouts can reach when that is less (at least
   ``min_clearance_scale``): a passage A* found, narrower than ``clearance_scale``, is
   followed without a penalty for being in it (with the fixed scale, standing still
   scored better than driving into a 0.2 m-wide squeeze by the lab's crate, and the base
   stood there, "stuck on the way to depot", though the path was free); ``speed``: ``1 - v / max_v``; ``social``: the
   largest social cost along the rollout, people moved at their velocity.

Outcomes for the caller (:class:`DwaStatus`): ``GOAL_REACHED``; ``NO_TRAJECTORY`` (no
admissible rollout: the command brakes); ``STUCK`` (the path progress has not improved by
``stuck_progress`` for ``stuck_time`` seconds: the caller recovers: rotate, back off,
re-plan). Independently, ``path_blocked`` reports an obstacle on the next
``blocked_lookahead`` metres of path (a costmap obstacle closer than the robot radius,
or a circle's safety zone; people excepted: they move on), so the caller re-plans
globally (:meth:`mmexec.skills.navigation.local_planner.LocalPlanner.replan_grid`).
A DWA that follows a path holds to it: an obstacle that intrudes on the path is passed
only as far as the path and clearance terms allow, and otherwise the base slows and
stops in front of it; going round is the re-plan's job.

Frames: ``map``; m, rad, s. The planner never reads a clock: the caller passes ``now``.
"""

from __future__ import annotations

import enum
import logging
import math
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from mmexec.drivers.interfaces import Pose2D
from mmexec.skills.navigation.checks import checked, non_negative, positive
from mmexec.skills.navigation.limits import BaseLimits
from mmexec.skills.navigation.obstacles import Circles
from mmexec.skills.navigation.social import SocialConfig, social_cost

__all__ = ["ClearanceMap", "DwaConfig", "DwaPlanner", "DwaResult", "DwaStatus", "PathFollower", "rollouts"]

log = logging.getLogger(__name__)


class ClearanceMap(Protocol):
    """Anything that gives the distance [m] to the nearest obstacle at map points (..., 2)."""

    def clearance_at(self, xy: np.ndarray) -> np.ndarray: ...


@dataclass(frozen=True)
class DwaConfig:
    """DWA tuning. Times in s, distances in m; weights are dimensionless."""

    limits: BaseLimits = field(default_factory=BaseLimits)
    horizon: float = 1.5
    step: float = 0.1
    window_time: float = 0.3
    n_v: int = 7
    n_w: int = 15
    lookahead: float = 0.5
    path_spacing: float = 0.05
    w_path: float = 1.0
    w_heading: float = 0.6
    w_goal: float = 1.0
    w_clearance: float = 1.0
    w_speed: float = 0.3
    w_social: float = 1.0
    path_scale: float = 0.5
    clearance_scale: float = 0.4
    min_clearance_scale: float = 0.05
    goal_tolerance: float = 0.08
    blocked_lookahead: float = 2.0
    stuck_time: float = 4.0
    stuck_progress: float = 0.10
    social: SocialConfig = field(default_factory=SocialConfig)

    def validate(self) -> list[str]:
        errs = self.limits.validate() + self.social.validate()
        errs += positive(self, "horizon", "step", "window_time", "lookahead", "path_spacing", "path_scale",
                         "clearance_scale", "min_clearance_scale", "goal_tolerance", "blocked_lookahead", "stuck_time",
                         "stuck_progress")
        if self.step > self.horizon:
            errs.append(f"step {self.step} s exceeds horizon {self.horizon} s")
        if self.n_v < 2 or self.n_w < 2:
            errs.append(f"n_v and n_w: need >= 2 samples each, got {self.n_v} and {self.n_w}")
        errs += non_negative(self, "w_path", "w_heading", "w_goal", "w_clearance", "w_speed", "w_social")
        return errs


class DwaStatus(enum.Enum):
    OK = "ok"
    GOAL_REACHED = "goal_reached"
    NO_TRAJECTORY = "no_trajectory"
    STUCK = "stuck"


@dataclass(frozen=True)
class DwaResult:
    """One tick's outcome: the command ``(v, w)`` [m/s, rad/s]; ``status``;
    ``path_blocked`` and ``blocked_at`` (path length [m] from the robot to the first
    blocked point, inf when clear); ``carrot`` (the path point ``lookahead`` ahead, with
    the path's heading there); ``remaining`` path length [m]; ``trajectory`` (K, 3) the
    chosen rollout's poses ``(x, y, theta)`` at ``step``, ``2 step``, ... (empty when none);
    ``n_admissible`` rollouts out of ``n_rollouts``."""

    v: float
    w: float
    status: DwaStatus
    path_blocked: bool
    blocked_at: float
    carrot: Pose2D
    remaining: float
    trajectory: np.ndarray
    n_admissible: int
    n_rollouts: int


def rollouts(pose: Pose2D, v0: float, w0: float, v_target: np.ndarray, w_target: np.ndarray, step: float,
             k: int, accel_v: float, accel_w: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rollouts of a unicycle starting at ``pose`` with velocity ``(v0, w0)`` that ramps at
    the full accelerations ``accel_v`` [m/s^2] and ``accel_w`` [rad/s^2] to each target
    ``(v_target[i], w_target[i])`` [m/s, rad/s] (N,) and then holds it. Returns the poses
    ``(x, y, theta)`` at ``step``, ``2 step``, ... ``k step`` [s], shape (N, k, 3), the
    forward speed [m/s] at those times and the distance [m] travelled by then, (N, k)
    each. Midpoint integration (exact for the piecewise
    linear speed; the arcs' error is O(step^2) per step)."""
    t_mid = (np.arange(k) + 0.5) * step
    t_end = (np.arange(k) + 1.0) * step
    dv = (v_target - v0)[:, None]
    dw = (w_target - w0)[:, None]
    v_mid = v0 + np.clip(dv, -accel_v * t_mid, accel_v * t_mid)
    w_mid = w0 + np.clip(dw, -accel_w * t_mid, accel_w * t_mid)
    th = pose.theta + np.cumsum(w_mid * step, axis=1)
    th_mid = th - 0.5 * step * w_mid
    ds = v_mid * step
    x = pose.x + np.cumsum(ds * np.cos(th_mid), axis=1)
    y = pose.y + np.cumsum(ds * np.sin(th_mid), axis=1)
    v_end = v0 + np.clip(dv, -accel_v * t_end, accel_v * t_end)
    return np.stack([x, y, th], axis=-1), v_end, np.cumsum(np.abs(ds), axis=1)


class PathFollower:
    """A path resampled every ``spacing`` metres, with monotone progress: the robot's
    projection never moves back along the path, and is searched only near the last one
    (so a path passing close to itself is not short-cut)."""

    def __init__(self, path: list[tuple[float, float]], spacing: float) -> None:
        if not path:
            raise ValueError("PathFollower: empty path")
        pts = np.asarray(path, dtype=float).reshape(-1, 2)
        seg = np.hypot(*np.diff(pts, axis=0).T) if len(pts) > 1 else np.zeros(0)
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        self.length = float(cum[-1])
        s = np.append(np.arange(0.0, self.length, spacing), self.length)
        self.points = np.stack([np.interp(s, cum, pts[:, 0]), np.interp(s, cum, pts[:, 1])], axis=1)
        self.s = s
        self.spacing = spacing
        self.index = 0
        d = np.diff(self.points, axis=0)
        heading = np.arctan2(d[:, 1], d[:, 0]) if len(d) else np.zeros(0)
        self.heading = np.append(heading, heading[-1] if len(heading) else 0.0)

    @property
    def goal(self) -> np.ndarray:
        return self.points[-1]

    def advance(self, x: float, y: float, search: float) -> int:
        """Move the progress index to the nearest sample within ``search`` metres of path
        ahead of (or slightly behind) the current one; returns it."""
        k = max(1, int(search / self.spacing))
        lo, hi = max(0, self.index - k // 4), min(len(self.points), self.index + k + 1)
        window = self.points[lo:hi]
        j = lo + int(np.argmin(np.hypot(window[:, 0] - x, window[:, 1] - y)))
        self.index = max(self.index, j)
        return self.index

    def ahead(self, distance: float) -> int:
        """Index of the sample ``distance`` metres ahead of the progress index (clamped)."""
        return min(len(self.points) - 1, self.index + round(distance / self.spacing))

    def remaining(self) -> float:
        return self.length - float(self.s[self.index])


def _wrap(a: np.ndarray) -> np.ndarray:
    return np.mod(a + np.pi, 2.0 * np.pi) - np.pi


class DwaPlanner:
    """DWA over a path; see the module docstring. :meth:`set_path` then :meth:`step` per tick."""

    def __init__(self, config: DwaConfig | None = None) -> None:
        self.config = checked(config or DwaConfig())
        k = max(1, round(self.config.horizon / self.config.step))
        self.times = self.config.step * np.arange(1, k + 1)
        self.path: PathFollower | None = None
        self._best_remaining = math.inf
        self._t_best = 0.0

    def set_path(self, path: list[tuple[float, float]], now: float) -> None:
        """Follow ``path`` (map points [m], e.g. from A*) from clock time ``now`` [s]."""
        self.path = PathFollower(path, self.config.path_spacing)
        self.reset_progress(now)

    def reset_progress(self, now: float) -> None:
        """Restart the stuck timer (after a recovery)."""
        self._best_remaining = math.inf if self.path is None else self.path.remaining()
        self._t_best = now

    # ------------------------------------------------------------------ pieces
    def window_samples(self, v0: float, w0: float, v_cap: float | None) -> tuple[np.ndarray, np.ndarray]:
        """Target ``(v, w)`` samples on an ``n_v x n_w`` grid over the velocities reachable
        within ``window_time`` (flattened, (N,) each); the yaw-rate sample nearest 0 is
        moved to exactly 0 when the window holds 0 (driving straight is always a candidate)."""
        cfg = self.config
        v_lo, v_hi, w_lo, w_hi = cfg.limits.window(v0, w0, cfg.window_time, v_cap)
        vs = np.linspace(v_lo, v_hi, cfg.n_v)
        ws = np.linspace(w_lo, w_hi, cfg.n_w)
        if w_lo <= 0.0 <= w_hi:
            ws[np.argmin(np.abs(ws))] = 0.0
        return np.repeat(vs, cfg.n_w), np.tile(ws, cfg.n_v)

    def gaps(self, traj: np.ndarray, start: Pose2D, costmap: ClearanceMap, circles: Circles) -> tuple[np.ndarray, np.ndarray]:
        """Gap [m] to the nearest obstacle along each rollout point (N, K), and the
        allowance (N, K) below which a point collides (0, or the start's own gap when the
        start is already inside, so rollouts that do not get closer stay admissible)."""
        r = self.config.limits.radius
        pts = traj[..., :2]
        xy0 = np.array([[start.x, start.y]])
        g_map = costmap.clearance_at(pts) - r
        g0_map = float(costmap.clearance_at(xy0)[0]) - r
        allow_map = min(0.0, g0_map)
        if len(circles):
            paths = circles.paths(self.times)[:, None]  # (k, 1, K, 2)
            g_i = np.hypot(pts[None, ..., 0] - paths[..., 0], pts[None, ..., 1] - paths[..., 1])
            g_i -= circles.safety_radii[:, None, None]
            d0 = np.hypot(circles.centres[:, 0] - start.x, circles.centres[:, 1] - start.y)
            allow_c = np.minimum(0.0, d0 - circles.safety_radii)  # per circle, like allow_map
            hit = (g_map < allow_map) | ((g_i - allow_c[:, None, None]).min(axis=0) < 0.0)
            gap = np.minimum(g_map, g_i.min(axis=0))
        else:
            hit = g_map < allow_map
            gap = g_map
        return gap, hit

    def path_blocked(self, pose: Pose2D, costmap: ClearanceMap, circles: Circles) -> float:
        """Path length [m] from the robot's projection to the first point, on the next
        ``blocked_lookahead`` metres of path, where the robot may not be: within the robot
        radius of a costmap obstacle or inside a circle's safety radius; people's zones
        are excepted (they move on). inf when the path ahead is clear."""
        p = self.path
        assert p is not None
        end = p.ahead(self.config.blocked_lookahead)
        pts = p.points[p.index : end + 1]
        r = self.config.limits.radius
        lethal = costmap.clearance_at(pts) < r
        if len(circles):
            d = np.hypot(pts[:, None, 0] - circles.centres[:, 0], pts[:, None, 1] - circles.centres[:, 1])
            inside = d < circles.safety_radii
            lethal |= inside[:, ~circles.person].any(axis=1)
            lethal &= ~inside[:, circles.person].any(axis=1)
        lethal &= np.hypot(pts[:, 0] - pose.x, pts[:, 1] - pose.y) > r  # not the robot's own spot
        if not lethal.any():
            return math.inf
        return float(np.argmax(lethal)) * p.spacing

    def path_gap(self, points: np.ndarray, costmap: ClearanceMap, circles: Circles) -> float:
        """The smallest gap [m] the path ``points`` (n, 2) leave the footprint: costmap
        clearance less the robot radius, and the distance outside each non-person
        circle's safety radius (people move on)."""
        g = costmap.clearance_at(points) - self.config.limits.radius
        fixed = circles.select(~circles.person)
        if len(fixed):
            d = np.hypot(points[:, None, 0] - fixed.centres[:, 0], points[:, None, 1] - fixed.centres[:, 1])
            g = np.minimum(g, (d - fixed.safety_radii).min(axis=1))
        return float(g.min()) if g.size else math.inf

    # ------------------------------------------------------------------ tick
    def step(self, pose: Pose2D, v0: float, w0: float, dt: float, now: float, costmap: ClearanceMap,
             circles: Circles, v_cap: float | None = None) -> DwaResult:
        """One tick: base ``pose`` in ``map``, current command ``(v0, w0)``, tick ``dt`` [s],
        clock ``now`` [s], obstacles (``costmap`` and tracked ``circles``), an optional
        forward speed cap [m/s] (e.g. the social scale times max_v)."""
        if self.path is None:
            raise RuntimeError("DwaPlanner.step: no path; call set_path() first")
        if not dt > 0:
            raise ValueError(f"DwaPlanner.step: dt must be > 0, got {dt}")
        cfg, lim, path = self.config, self.config.limits, self.path
        path.advance(pose.x, pose.y, cfg.lookahead + 1.0)
        ci = path.ahead(cfg.lookahead)
        carrot = Pose2D(float(path.points[ci, 0]), float(path.points[ci, 1]), float(path.heading[ci]))
        remaining = path.remaining()
        people = circles.people
        blocked_at = self.path_blocked(pose, costmap, circles)
        goal = path.goal
        d_goal = math.hypot(goal[0] - pose.x, goal[1] - pose.y)

        def result(v: float, w: float, status: DwaStatus, traj: np.ndarray, n_ok: int, n: int) -> DwaResult:
            return DwaResult(v, w, status, math.isfinite(blocked_at), blocked_at, carrot, remaining, traj, n_ok, n)

        if d_goal <= cfg.goal_tolerance:
            v, w = lim.brake(v0, w0, dt)
            return result(v, w, DwaStatus.GOAL_REACHED, np.zeros((0, 3)), 0, 0)

        stop_cap = math.sqrt(2.0 * lim.accel_v * max(0.0, max(remaining, d_goal) - 0.5 * cfg.goal_tolerance))
        cap = stop_cap if v_cap is None else min(v_cap, stop_cap)
        lo = max(0, path.index - 2)
        local = path.points[lo : path.ahead(lim.max_v * cfg.horizon + 0.5) + 1]
        ahead = local[np.hypot(local[:, 0] - pose.x, local[:, 1] - pose.y) > lim.radius]  # not the base's own spot
        path_gap = self.path_gap(ahead, costmap, circles)
        vs, ws = self.window_samples(v0, w0, cap)
        traj, speed, dist = rollouts(pose, v0, w0, vs, ws, cfg.step, self.times.size, lim.accel_v, lim.accel_w)
        gap, hit = self.gaps(traj, pose, costmap, circles)
        # admissible: no hit, or the base can brake to a stop before the first hit
        any_hit = hit.any(axis=1)
        first = np.argmax(hit, axis=1)
        rows, before = np.arange(vs.size), np.maximum(first - 1, 0)
        travelled = np.where(first > 0, dist[rows, before], 0.0)
        v_before = np.where(first > 0, np.abs(speed[rows, before]), abs(v0))
        admissible = ~any_hit | (travelled >= v_before**2 / (2.0 * lim.accel_v) - 1e-12)

        # the end point against the path: cross-track distance, progress along it, and the
        # heading towards the path point ``lookahead`` beyond the end point's projection
        end = traj[:, -1, :]
        d_end = np.hypot(end[:, None, 0] - local[:, 0], end[:, None, 1] - local[:, 1])
        j = np.argmin(d_end, axis=1)
        cross = d_end[np.arange(vs.size), j]
        progress = (lo + j - path.index) * path.spacing
        aim = path.points[np.minimum(lo + j + round(cfg.lookahead / path.spacing), len(path.points) - 1)]
        to_aim = np.hypot(aim[:, 0] - end[:, 0], aim[:, 1] - end[:, 1])
        bearing = np.arctan2(aim[:, 1] - end[:, 1], aim[:, 0] - end[:, 0])
        heading_err = np.where(to_aim > cfg.goal_tolerance, np.abs(_wrap(bearing - end[:, 2])) / math.pi, 0.0)
        min_gap = np.clip(gap.min(axis=1), 0.0, None)
        # 0..1 by the smallest gap against what the path itself leaves; 1..3 for an
        # (admissible) rollout that hits, sooner = worse
        scale = min(cfg.clearance_scale, max(cfg.min_clearance_scale, path_gap))
        t_hit = np.where(any_hit, self.times[first], np.inf)
        clearance = np.where(any_hit, 3.0 - 2.0 * t_hit / cfg.horizon, 1.0 - np.minimum(min_gap / scale, 1.0))
        cost = (cfg.w_path * cross / cfg.path_scale
                + cfg.w_heading * heading_err
                - cfg.w_goal * progress / (lim.max_v * cfg.horizon)
                + cfg.w_clearance * clearance
                + cfg.w_speed * (1.0 - vs / lim.max_v))
        if len(people) and cfg.w_social > 0:
            soc = social_cost(traj[..., :2], people.paths(self.times)[:, None], cfg.social).max(axis=1)
            cost = cost + cfg.w_social * soc
        n_ok = int(admissible.sum())

        # stuck detector: best remaining path length must improve by stuck_progress
        if remaining < self._best_remaining - cfg.stuck_progress:
            self._best_remaining, self._t_best = remaining, now
        stuck = now - self._t_best > cfg.stuck_time

        if n_ok == 0:
            v, w = lim.brake(v0, w0, dt)
            log.debug("dwa: no admissible rollout of %d at (%.2f, %.2f)", vs.size, pose.x, pose.y)
            return result(v, w, DwaStatus.STUCK if stuck else DwaStatus.NO_TRAJECTORY, np.zeros((0, 3)), 0, vs.size)
        best = int(np.argmin(np.where(admissible, cost, np.inf)))
        status = DwaStatus.STUCK if stuck else DwaStatus.OK
        # the command: the first tick of the chosen ramp
        v_lo, v_hi, w_lo, w_hi = lim.window(v0, w0, dt, cap)
        v = min(max(float(vs[best]), v_lo), v_hi)
        w = min(max(float(ws[best]), w_lo), w_hi)
        return result(v, w, status, traj[best], n_ok, vs.size)
