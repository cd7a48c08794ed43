"""CLF-CBF quadratic-program safety filter on ``(v, w)`` for a unicycle base.

The formulation is that of the UR3e hierarchical-planning paper, section 4, on the
unicycle ``xdot = v cos th, ydot = v sin th, thdot = w`` (control-affine, ``f = 0``).
Decision variables ``z = (v, w, mu)``::

    minimise   (u - u_ref)^T H (u - u_ref) + p mu^2
    subject to LgV u + lambda V <= mu                    (CLF, relaxed by mu >= 0)
               Lgh_i u + Lfh_i + alpha h_i >= 0          (one CBF per obstacle circle)
               v, w within the velocity limits and reachable within dt (acceleration)

**CLF** (section 4.2): ``V = 1/2 e^T e + beta sin(delta)``, ``e = (x_r - x, y_r - y)``,
``delta = |th_r - th| / 2`` (the angle difference wrapped to (-pi, pi], so delta lies
in [0, pi/2] where sin is increasing). The reference ``(x_r, y_r, th_r)`` is held fixed
over the tick, so ``LfV = 0`` and ``LgV = (-(e_x cos th + e_y sin th),
-(beta / 2) cos(delta) sgn(th_r - th))`` (0 for the heading part when the headings are
equal, where ``|.|`` has no derivative and the term is at its minimum). Which path the
CLF tracks is the caller's choice: :class:`mmexec.skills.navigation.local_planner.LocalPlanner`
passes the pose the DWA's chosen rollout reaches ``reference_time`` seconds ahead, the
local refinement of the A* path the paper's hierarchy hands to this controller, so the
CLF and ``u_ref`` agree and ``mu`` grows only when a barrier bends the command away.

**CBF** (section 4.3): the paper's ``h = (x - x_u)^2 + (y - y_u)^2 - r_u^2`` depends on
the position only, so ``hdot = 2 (p - c) . (v cos th, v sin th)`` holds no ``w``: the
unicycle has relative degree 2 in ``w`` and such a filter can only brake, never steer
round. We use the standard look-ahead workaround: the barrier is written for the point
``p_l = (x + l cos th, y + l sin th)`` a distance ``l`` ahead of the axle centre, whose
velocity ``(v cos th - l w sin th, v sin th + l w cos th)`` holds both inputs, and the
radius grows by ``l``: ``h = |p_l - c|^2 - (r_u + l)^2``. Then ``h >= 0`` implies
``|p - c| >= |p_l - c| - l >= r_u``, so the paper's safe set is kept (conservatively by at
most ``l``). ``r_u`` is the circle's safety radius: covering radius + robot radius +
margin (the paper's over-approximation). A moving obstacle (tracked velocity ``c_dot``)
adds the drift ``Lfh = -2 (p_l - c) . c_dot``; the paper's obstacles are static (0).

**alpha** (section 4.3 and the experiments): the standard condition used here is
``hdot >= -alpha h``: alpha bounds how fast ``h`` may *decrease* (h decays at most as
``exp(-alpha t)``), and forward invariance of ``h >= 0`` holds for any alpha > 0. The
paper calls alpha "the lower bound of the decreasing rate" and raises it from 0.21 to
0.46 in tight spaces "to emphasize the CBF-derived safety constraint". Under the
standard condition that runs the other way: a larger alpha *relaxes* the constraint (the
base may close on an obstacle twice as fast and brakes later), which is plausibly what
let the paper's robot pass between rows of chairs. We keep the standard condition and
the paper's structure (one alpha in the open, a larger one when two or more circles are
within ``tight_gap`` of the robot, a passage, with the CLF rate lowered to ``lam_tight``
there, as the paper does) but not its numbers: with ``alpha = 0.21`` [1/s] passing an
obstacle at distance D caps the speed near ``alpha sqrt(D^2 - R^2)`` (0.1-0.15 m/s with
0.3 m to spare), so the base crawled three times slower among people and stood whenever
someone walked towards it. The defaults are ``alpha = 1.0`` and ``alpha_tight = 2.0``
[1/s] (:data:`PAPER_ALPHA` and :data:`PAPER_ALPHA_TIGHT` keep the paper's for
comparisons; benchmarks/local_planner.py runs both). Safety, in the tight case too,
comes from the barrier itself, not from the choice of alpha. The condition is imposed on the continuous-time derivative while the
command is held for a tick ``dt``; with ``alpha dt << 1`` (0.05-0.1 at 20 Hz) the sampling
error is second order in ``dt``, and the look-ahead's extra ``l`` covers it in practice.

**Solver**: DAQP (a dual active-set solver for dense QPs; ``daqp.solve``), a few
microseconds for these 3-variable problems. An infeasible QP (the barriers cannot all be
met within the acceleration bounds, e.g. a person walking into a braking robot) is
reported as :attr:`QpStatus.INFEASIBLE` and the command brakes at full deceleration.

Frames: ``map``; m, rad, s; ``h`` in m^2, ``V`` in m^2.
"""

from __future__ import annotations

import enum
import logging
import math
from dataclasses import dataclass, field

import daqp
import numpy as np

from mmexec.drivers.interfaces import Pose2D
from mmexec.skills.navigation.checks import checked, non_negative, positive
from mmexec.skills.navigation.limits import BaseLimits
from mmexec.skills.navigation.obstacles import Circles

__all__ = ["PAPER_ALPHA", "PAPER_ALPHA_TIGHT", "CbfConfig", "CbfFilter", "CbfQp", "CbfResult", "QpStatus", "barrier", "build_qp", "solve_qp"]

log = logging.getLogger(__name__)

#: DAQP's infinity (bounds at or beyond it are absent)
QP_INF = 1e30


#: [1/s] the UR3e paper's alpha in the open and in tight spaces (section 4.3), for
#: comparisons; :class:`CbfConfig`'s defaults are larger (module docstring)
PAPER_ALPHA, PAPER_ALPHA_TIGHT = 0.21, 0.46


@dataclass(frozen=True)
class CbfConfig:
    """Filter parameters: ``alpha``, ``alpha_tight``, ``lam``, ``lam_tight`` [1/s];
    ``tight_gap`` [m]; ``beta`` [m^2] heading weight of V; ``slack_weight`` p [s^2/m^4]
    (mu is in m^2/s); ``weight_v`` [s^2/m^2] and ``weight_w`` [s^2/rad^2], the diagonal
    of H; ``lookahead`` l [m]; the base's ``limits``."""

    limits: BaseLimits = field(default_factory=BaseLimits)
    alpha: float = 1.0
    alpha_tight: float = 2.0
    tight_gap: float = 0.30
    lam: float = 1.0
    lam_tight: float = 0.5
    beta: float = 0.3
    slack_weight: float = 50.0
    weight_v: float = 1.0
    weight_w: float = 0.1
    lookahead: float = 0.10

    def validate(self) -> list[str]:
        errs = self.limits.validate()
        errs += positive(self, "alpha", "alpha_tight", "lam", "lam_tight", "slack_weight", "weight_v", "weight_w",
                         "lookahead")
        errs += non_negative(self, "beta", "tight_gap")
        return errs


class QpStatus(enum.Enum):
    OPTIMAL = "optimal"
    INFEASIBLE = "infeasible"


@dataclass(frozen=True)
class CbfQp:
    """``min 1/2 z^T H z + f^T z`` s.t. ``A z <= b`` and ``lower <= z <= upper``, with
    ``z = (v, w, mu)``; row 0 of ``A`` is the CLF (when ``has_clf``), the rest the CBFs.
    ``h`` (k,) the barrier values [m^2], ``V`` the CLF value [m^2]."""

    H: np.ndarray
    f: np.ndarray
    A: np.ndarray
    b: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    has_clf: bool
    h: np.ndarray
    V: float
    alpha: float
    tight: bool

    @property
    def cbf_rows(self) -> slice:
        return slice(1 if self.has_clf else 0, self.A.shape[0])


@dataclass(frozen=True)
class CbfResult:
    """The filtered command ``(v, w)`` [m/s, rad/s], the CLF slack ``mu`` [m^2/s],
    ``status``, barrier values ``h`` (k,) [m^2] at the current state, ``active`` (k,)
    True where a barrier constraint binds (non-zero multiplier), and the ``alpha`` used
    (``tight`` when ``alpha_tight``)."""

    v: float
    w: float
    mu: float
    status: QpStatus
    h: np.ndarray
    active: np.ndarray
    alpha: float
    tight: bool
    V: float


def _offsets(pose: Pose2D, circles: Circles, lookahead: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``p_l - c_i`` (x and y parts) and ``h_i`` at the look-ahead point of ``pose``."""
    dx = pose.x + lookahead * math.cos(pose.theta) - circles.centres[:, 0]
    dy = pose.y + lookahead * math.sin(pose.theta) - circles.centres[:, 1]
    return dx, dy, dx * dx + dy * dy - (circles.safety_radii + lookahead) ** 2


def barrier(pose: Pose2D, circles: Circles, lookahead: float) -> np.ndarray:
    """``h_i = |p_l - c_i|^2 - (r_u,i + l)^2`` [m^2] at the look-ahead point of ``pose``."""
    return _offsets(pose, circles, lookahead)[2]


def build_qp(pose: Pose2D, u_ref: tuple[float, float], reference: Pose2D | None, circles: Circles,
             u_prev: tuple[float, float], dt: float, config: CbfConfig, v_cap: float | None = None) -> CbfQp:
    """The QP of one tick: base ``pose`` in ``map``, nominal command ``u_ref``, CLF
    ``reference`` pose (None: no CLF row), obstacle ``circles``, previous command
    ``u_prev`` and tick ``dt`` [s] (for the acceleration bounds), optional forward speed
    cap [m/s]."""
    cfg, lim, l = config, config.limits, config.lookahead
    c, s = math.cos(pose.theta), math.sin(pose.theta)
    gap = np.hypot(circles.centres[:, 0] - pose.x, circles.centres[:, 1] - pose.y) - circles.safety_radii
    tight = int(np.count_nonzero(gap < cfg.tight_gap)) >= 2
    alpha = cfg.alpha_tight if tight else cfg.alpha
    lam = cfg.lam_tight if tight else cfg.lam
    dx, dy, h = _offsets(pose, circles, l)
    lgh_v = 2.0 * (dx * c + dy * s)
    lgh_w = 2.0 * l * (-dx * s + dy * c)
    lfh = -2.0 * (dx * circles.velocities[:, 0] + dy * circles.velocities[:, 1])
    rows = [np.stack([-lgh_v, -lgh_w, np.zeros_like(h)], axis=1)]
    rhs = [lfh + alpha * h]
    V = 0.0
    if reference is not None:
        ex, ey = reference.x - pose.x, reference.y - pose.y
        dth = math.atan2(math.sin(reference.theta - pose.theta), math.cos(reference.theta - pose.theta))
        delta = abs(dth) / 2.0
        V = 0.5 * (ex * ex + ey * ey) + cfg.beta * math.sin(delta)
        lgv = (-(ex * c + ey * s), -0.5 * cfg.beta * math.cos(delta) * float(np.sign(dth)))
        rows.insert(0, np.array([[lgv[0], lgv[1], -1.0]]))
        rhs.insert(0, np.array([-lam * V]))
    v_lo, v_hi, w_lo, w_hi = lim.window(u_prev[0], u_prev[1], dt, v_cap)
    wv, ww = cfg.weight_v, cfg.weight_w
    return CbfQp(
        H=np.diag([2.0 * wv, 2.0 * ww, 2.0 * cfg.slack_weight]),
        f=np.array([-2.0 * wv * u_ref[0], -2.0 * ww * u_ref[1], 0.0]),
        A=np.ascontiguousarray(np.concatenate(rows, axis=0)),
        b=np.concatenate(rhs),
        lower=np.array([v_lo, w_lo, 0.0]),
        upper=np.array([v_hi, w_hi, QP_INF]),
        has_clf=reference is not None,
        h=h,
        V=V,
        alpha=alpha,
        tight=tight,
    )


def solve_qp(qp: CbfQp) -> tuple[np.ndarray, QpStatus, np.ndarray]:
    """Solve with DAQP: the minimiser ``z``, the status, and the multipliers of the rows
    of ``A`` (>= 0; 0 for inactive rows). ``z`` is nan when infeasible."""
    m = qp.A.shape[0]
    bupper = np.concatenate([qp.upper, qp.b])
    blower = np.concatenate([qp.lower, np.full(m, -QP_INF)])
    sense = np.zeros(3 + m, dtype=np.int32)
    z, _, flag, info = daqp.solve(qp.H, qp.f, qp.A, bupper, blower, sense)
    if flag in (1, 2):
        return np.asarray(z, dtype=float), QpStatus.OPTIMAL, np.asarray(info["lam"], dtype=float)[3:]
    if flag != -1:
        log.warning("DAQP ended with exit flag %d (not optimal, not infeasible); treating as infeasible", flag)
    return np.full(3, np.nan), QpStatus.INFEASIBLE, np.zeros(m)


class CbfFilter:
    """The safety filter; stateless apart from its configuration."""

    def __init__(self, config: CbfConfig | None = None) -> None:
        self.config = checked(config or CbfConfig())

    def filter(self, pose: Pose2D, u_ref: tuple[float, float], reference: Pose2D | None, circles: Circles,
               u_prev: tuple[float, float], dt: float, v_cap: float | None = None) -> CbfResult:
        """The command closest to ``u_ref`` (in the H metric) that meets every barrier and
        the bounds, tracking ``reference`` as far as the slack allows; see :func:`build_qp`.
        When the QP is infeasible the command brakes at full deceleration from ``u_prev``."""
        qp = build_qp(pose, u_ref, reference, circles, u_prev, dt, self.config, v_cap)
        z, status, lam = solve_qp(qp)
        rows = qp.cbf_rows
        if status is QpStatus.OPTIMAL:
            return CbfResult(float(z[0]), float(z[1]), float(z[2]), status, qp.h, lam[rows] > 1e-9,
                             qp.alpha, qp.tight, qp.V)
        v, w = self.config.limits.brake(u_prev[0], u_prev[1], dt)
        log.debug("CBF QP infeasible at (%.2f, %.2f, %.2f), min h %.3f m^2: braking", pose.x, pose.y,
                    pose.theta, float(qp.h.min()) if qp.h.size else math.nan)
        return CbfResult(v, w, 0.0, status, qp.h, np.zeros(qp.h.shape, dtype=bool), qp.alpha, qp.tight, qp.V)
