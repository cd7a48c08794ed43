"""Social layer: a Gaussian cost around tracked people, and a speed limit near them.

As in the LoCoBot fetch architecture's social navigation layer (a Gaussian-based costmap
around humans), a person at ``c`` costs ``amplitude * exp(-|p - c|^2 / (2 sigma^2))`` at
map point ``p``; several people combine by the maximum (as costmap layers do), so the
cost never exceeds ``amplitude``, and it is cut to 0 beyond ``cutoff`` sigmas.

Speed near people: the forward speed limit falls linearly with the *gap* (centre
distance minus the person's covering radius minus the robot radius) from the full speed
at ``slow_gap`` to ``min_scale`` of it at ``stop_gap`` and below. A person is never
approached at full speed, and the robot still creeps past one in a corridor.

Waiting for people (:class:`PeopleWait`): while someone the tracker knows as a person
(moving, or standing after having moved) is within ``slow_gap`` of the base, the base is
giving way, not stuck: people move on (a person who stops in the way, at a viewpoint or
by the goal, walks on within seconds; the sim's people turn round after 3 s). The
patience is bounded: after ``patience`` seconds of people near the base in one stretch
the wait is spent, the drive's stuck recovery counts again, and its re-plans go round
the people standing there; a new drive, or a recovery, starts a new stretch (:meth:`mmexec.skills.navigation.local_planner.LocalPlanner.replan_grid`).

Frames: ``map``; metres, seconds. The cost is dimensionless (the DWA weighs it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mmexec.skills.navigation.checks import non_negative, positive
from mmexec.skills.navigation.obstacles import Circles

__all__ = ["PeopleWait", "SocialConfig", "social_cost", "speed_scale"]


@dataclass(frozen=True)
class SocialConfig:
    """``amplitude`` (cost at a person's centre, >= 0), ``sigma`` [m], ``cutoff`` [sigmas];
    speed scaling: full speed at a gap of ``slow_gap`` [m] or more, ``min_scale`` (0-1)
    of it at ``stop_gap`` [m] or less; ``robot_radius`` [m]; ``patience`` [s], how long
    the base waits for people near it in one stretch (:class:`PeopleWait`)."""

    amplitude: float = 1.0
    sigma: float = 0.5
    cutoff: float = 3.0
    slow_gap: float = 1.2
    stop_gap: float = 0.3
    min_scale: float = 0.3
    robot_radius: float = 0.178
    patience: float = 10.0

    def validate(self) -> list[str]:
        errs = non_negative(self, "amplitude", "patience") + positive(self, "sigma", "cutoff")
        if not 0 <= self.stop_gap < self.slow_gap:
            errs.append(f"need 0 <= stop_gap < slow_gap, got {self.stop_gap} and {self.slow_gap}")
        if not 0 < self.min_scale <= 1:
            errs.append(f"min_scale: must be in (0, 1], got {self.min_scale}")
        return errs


def social_cost(points: np.ndarray, centres: np.ndarray, config: SocialConfig) -> np.ndarray:
    """Social cost at map points ``points`` (..., 2) [m] of people at ``centres``: (k, 2),
    or (k, ..., 2) broadcastable against ``points`` (e.g. people predicted at each
    rollout time, (k, 1, K, 2) for rollout points (N, K, 2)). Returns ``points.shape[:-1]``;
    0 without people."""
    k = centres.shape[0]
    if k == 0:
        return np.zeros(points.shape[:-1])
    c = centres if centres.ndim > 2 else centres.reshape(k, *([1] * (points.ndim - 1)), 2)
    d2 = ((points[None, ..., 0] - c[..., 0]) ** 2 + (points[None, ..., 1] - c[..., 1]) ** 2).min(axis=0)
    cost = config.amplitude * np.exp(-d2 / (2.0 * config.sigma**2))
    return np.where(d2 <= (config.cutoff * config.sigma) ** 2, cost, 0.0)


def speed_scale(position: tuple[float, float], people: Circles, config: SocialConfig) -> float:
    """Factor in ``[min_scale, 1]`` for the forward speed limit of a robot centred at map
    point ``position`` [m], from the nearest person's gap (see the module docstring)."""
    if len(people) == 0:
        return 1.0
    d = np.hypot(people.centres[:, 0] - position[0], people.centres[:, 1] - position[1])
    gap = float(np.min(d - people.radii)) - config.robot_radius
    frac = (gap - config.stop_gap) / (config.slow_gap - config.stop_gap)
    return float(min(1.0, max(config.min_scale, config.min_scale + (1.0 - config.min_scale) * frac)))


class PeopleWait:
    """Bounded patience with people near the base (see the module docstring): call
    :meth:`update` once per tick; :attr:`spent` once the patience ran out in the current
    stretch (it stays spent until nobody is within ``slow_gap``)."""

    #: [s] a tick longer than this (the clock stood, the drive paused) counts as this
    MAX_STEP = 0.5

    def __init__(self, config: SocialConfig) -> None:
        self.config = config
        self.waited = 0.0  #: [s] waited in the current stretch
        self._last: float | None = None

    @property
    def spent(self) -> bool:
        return self.waited > self.config.patience

    def reset(self) -> None:
        """A fresh stretch (a new drive, or after a recovery)."""
        self.waited, self._last = 0.0, None

    def update(self, people: Circles, position: tuple[float, float], now: float, standing: bool = True) -> bool:
        """True while the base should wait for ``people`` (tracked people, ``map``) near
        ``position`` [m] at clock time ``now`` [s]: someone within ``slow_gap`` and the
        patience not yet spent. Only time the base spends ``standing`` (or creeping) is
        counted against the patience."""
        dt = 0.0 if self._last is None else min(max(now - self._last, 0.0), self.MAX_STEP)
        self._last = now
        cfg = self.config
        if len(people):
            d = np.hypot(people.centres[:, 0] - position[0], people.centres[:, 1] - position[1])
            near = bool(np.any(d - people.radii - cfg.robot_radius < cfg.slow_gap))
        else:
            near = False
        if not near:
            self.waited = 0.0
            return False
        if standing:
            self.waited += dt
        return not self.spent
