"""Differential-drive odometry motion model, sampled for a whole particle set at once.

Probabilistic Robotics (Thrun, Burgard, Fox), table 5.6 ``sample_motion_model_odometry``, as
ROS ``amcl`` implements it (``odom_model_type: diff-corrected`` noise terms): the odometry
step between two raw odometry poses is decomposed into a first rotation ``rot1``, a
translation ``trans`` and a second rotation ``rot2``; each is perturbed with zero-mean
Gaussian noise whose standard deviation grows with the motion:

* ``sd(rot1) = sqrt(alpha1 * rot1^2 + alpha2 * trans^2)``
* ``sd(trans) = sqrt(alpha3 * trans^2 + alpha4 * (rot1^2 + rot2^2))``
* ``sd(rot2) = sqrt(alpha1 * rot2^2 + alpha2 * trans^2)``

alpha1 [rad^2/rad^2] rotation noise from rotation, alpha2 [rad^2/m^2] rotation noise from
translation, alpha3 [m^2/m^2] translation noise from translation, alpha4 [m^2/rad^2]
translation noise from rotation. As in ROS, a backwards step does not count as a half turn
in the noise (``rot`` is measured to the nearer of 0 and pi) and ``rot1`` is 0 for a step
shorter than 1 cm (a pure rotation).

Poses are ``(x [m], y [m], theta [rad])`` rows in the odometry (``odom``) frame for the
odometry and in ``map`` for the particles.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mmexec.drivers.geometry import wrap_angle as wrap

__all__ = ["OdometryNoise", "odometry_step", "sample_odometry_motion"]


@dataclass(frozen=True)
class OdometryNoise:
    """The motion model's alpha1..alpha4 (ROS ``odom_alpha1..4``).

    Default 0.05 each: a standard deviation of about 22 % of the step (ROS's 0.2 is 45 %).
    On the sim LoCoBot with the ``realistic`` odometry (2 % scale error, 1 % gyro scale
    error, gyro bias) 0.05 gave the lowest error of 0.01, 0.02, 0.05 and 0.2 for both the
    plain and the enhanced filter (benchmarks/results/localization.md). Raise them for a
    base that slips more (carpet, worn tyres): the cloud must cover the odometry's real
    error over one update."""

    alpha1: float = 0.05
    alpha2: float = 0.05
    alpha3: float = 0.05
    alpha4: float = 0.05


def odometry_step(prev: np.ndarray, now: np.ndarray) -> tuple[float, float, float]:
    """``(rot1 [rad], trans [m], rot2 [rad])`` of the step between odometry poses ``prev``
    and ``now`` (each ``(x, y, theta)``)."""
    dx, dy = float(now[0] - prev[0]), float(now[1] - prev[1])
    trans = math.hypot(dx, dy)
    rot1 = 0.0 if trans < 0.01 else float(wrap(math.atan2(dy, dx) - prev[2]))
    rot2 = float(wrap(now[2] - prev[2] - rot1))
    return rot1, trans, rot2


def _noise_angle(a: float) -> float:
    """``a`` measured to the nearer of 0 and pi: a backwards step is not a half turn."""
    return min(abs(float(wrap(a))), abs(float(wrap(a - math.pi))))


def sample_odometry_motion(
    particles: np.ndarray,
    prev: np.ndarray,
    now: np.ndarray,
    noise: OdometryNoise,
    rng: np.random.Generator,
) -> np.ndarray:
    """Particles ``(N, 3)`` moved by the odometry step ``prev -> now`` with sampled noise.

    Returns a new array; ``particles`` is not modified.
    """
    rot1, trans, rot2 = odometry_step(prev, now)
    r1n, r2n = _noise_angle(rot1), _noise_angle(rot2)
    n = len(particles)
    sd_rot1 = math.sqrt(noise.alpha1 * r1n * r1n + noise.alpha2 * trans * trans)
    sd_trans = math.sqrt(noise.alpha3 * trans * trans + noise.alpha4 * (r1n * r1n + r2n * r2n))
    sd_rot2 = math.sqrt(noise.alpha1 * r2n * r2n + noise.alpha2 * trans * trans)
    rot1_hat = rot1 - rng.normal(0.0, sd_rot1, n) if sd_rot1 > 0 else np.full(n, rot1)
    trans_hat = trans - rng.normal(0.0, sd_trans, n) if sd_trans > 0 else np.full(n, trans)
    rot2_hat = rot2 - rng.normal(0.0, sd_rot2, n) if sd_rot2 > 0 else np.full(n, rot2)
    out = np.empty_like(particles, dtype=np.float64)
    heading = particles[:, 2] + rot1_hat
    out[:, 0] = particles[:, 0] + trans_hat * np.cos(heading)
    out[:, 1] = particles[:, 1] + trans_hat * np.sin(heading)
    out[:, 2] = wrap(heading + rot2_hat)
    return out
