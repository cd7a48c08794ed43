"""CLF-CBF quadratic-program safety filter on ``(v, w)`` for a unicycle base.

The formulation is that of the UR3e hierarchical-planning paper, section 4, on the
unicycle ``xdot = v cos th, ydot = v sin th, thdot = w`` (control-affine, ``f = 0``).
Decision variables ``z = (v, w, mu, s)``::

    minimise   (u - u_ref)^T H (u - u_ref) + p mu^2 + q s^2
    subject to LgV u + lambda V <= mu                    (CLF, relaxed by mu >= 0)
               Lgh_i u + Lfh_i + alpha h_i >= 0          (one CBF per obstacle circle)
               Lgg_i u + Lfg_i + alpha g_i >= -s         (steering, while driven forward)
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

**CBF** (section 4.3), kept where the paper puts it: ``h_i = (x - x_u)^2 + (y - y_u)^2 -
r_u^2`` at the axle centre ``p = (x, y)``, one per obstacle circle, with ``r_u`` the
obstacle's covering radius (the over-approximation: the obstacle confined in a circle,
:mod:`mmexec.skills.navigation.obstacles`) + the robot's footprint radius + a stated
``margin`` (the profile's ``nav.margin``). ``h >= 0`` is then exactly "the footprint circle
is at least ``margin`` clear of the obstacle's circle": the barrier is the physical
clearance less the margin, measured on the circles, and the value the filter enforces is
the value logged (``nav_tick``'s ``h``, the smallest over the circles, at the pose the QP
was built at). A moving obstacle (tracked velocity ``c_dot``) adds the drift
``Lfh = -2 (p - c) . c_dot``; the paper's obstacles are static (0).

**Steering** (relaxed rows): ``hdot = 2 (p - c) . (v cos th, v sin th) + Lfh`` holds no
``w`` (the unicycle has relative degree 2 in ``w``), so the barrier alone can only slow
the base, stop it, or move it along its heading. While the nominal command drives the
base forward (``v_ref > 0``), one more row per circle bends it round: the usual
look-ahead barrier ``g_i = |p_l - c_i|^2 - (r_u + l)^2`` at ``p_l = p + l (cos th, sin
th)``, whose derivative holds ``w`` (``Lgg = (2 (p_l - c) . e_th, 2 l (p_l - c) . e_perp)``),
relaxed by the slack ``s >= 0`` weighted ``q`` (:attr:`CbfConfig.steer_weight`): the
filter turns away from a circle it closes on, as far as a turn costs less than the
slack, and the hard barrier ``h`` still bounds what it may do. ``g >= 0`` implies ``h >=
0`` but asks up to ``2 l`` more clearance facing a circle; the previous filter enforced
it as *the* barrier, and the people of the crowd campaigns, who stop 0.3 m from the
footprint, stood inside its zone at 36 % of the logged ticks while the forward-only base
could not restore it (and the log called that ``h < 0``). Neither happens with ``g``
relaxed, and with no steering rows when the base is told to stand.

**Escape** (a bounded reverse, or forward, motion): a base that may only brake cannot
restore ``h`` once someone steps inside the zone (``h < 0`` asks for ``hdot > 0``: moving
away). The QP is first solved within the nominal bounds (forward only, capped by the
caller). When that is infeasible, the escape solve (:func:`escape_qp`) takes the command
closest to standing still with ``v`` in ``[-e_back, e_fwd]`` (within the acceleration
bound), ``e`` at most :attr:`CbfConfig.escape_speed` and limited by the room the caller
measured behind and ahead on the lidar costmap (the lidar sees 360 degrees; the base has
no rear bumper), and every barrier relaxed by one heavily weighted slack: the base backs
away (or moves on) as far as that keeps or restores the barriers, and stands where no
motion along its heading helps (someone walking into its side, which a unicycle cannot
get out of the way of). Without room it brakes at full deceleration. (The local planner
gives it room behind only, and none while docking: ``LocalPlanner.safe``.)

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
comes from the barrier itself, not from the choice of alpha. The condition is imposed on
the continuous-time derivative while the command is held for a tick ``dt``; with ``alpha
dt << 1`` (0.05-0.1 at 20 Hz) the sampling error is second order in ``dt`` (and of the
safe sign on a straight line past a static circle, where ``h`` is convex in time); the
margin covers the rest.

**Solver**: DAQP (a dual active-set solver for dense QPs; ``daqp.solve``), a few
microseconds for these 4-variable problems. A QP infeasible with the escape too (the
barriers cannot all be met within the acceleration bounds, e.g. a person walking into the
side of a braking robot) is reported as :attr:`QpStatus.INFEASIBLE` and the command
brakes at full deceleration; :attr:`CbfResult.escaped` marks a command from the escape
solve.

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
from mmexec.skills.navigation.limits import BaseLimits, reachable
from mmexec.skills.navigation.obstacles import Circles

__all__ = ["PAPER_ALPHA", "PAPER_ALPHA_TIGHT", "CbfConfig", "CbfFilter", "CbfQp", "CbfResult", "QpStatus", "barrier",
           "build_qp", "escape_qp", "solve_qp"]

log = logging.getLogger(__name__)

#: DAQP's infinity (bounds at or beyond it are absent)
QP_INF = 1e30
#: [s^2/m^4] weight of the escape solve's barrier slack (:func:`escape_qp`): large, so
#: any motion that keeps a barrier is taken
ESCAPE_SLACK_WEIGHT = 1e4
#: [m^2/s] an escape slack at most this is "every barrier kept" (the slack's weight
#: leaves it a few 1e-6 above 0 where a barrier binds)
ESCAPE_KEPT = 1e-4


#: [1/s] the UR3e paper's alpha in the open and in tight spaces (section 4.3), for
#: comparisons; :class:`CbfConfig`'s defaults are larger (module docstring)
PAPER_ALPHA, PAPER_ALPHA_TIGHT = 0.21, 0.46


@dataclass(frozen=True)
class CbfConfig:
    """Filter parameters: ``alpha``, ``alpha_tight``, ``lam``, ``lam_tight`` [1/s];
    ``tight_gap`` [m]; ``beta`` [m^2] heading weight of V; ``slack_weight`` p [s^2/m^4]
    (mu is in m^2/s); ``weight_v`` [s^2/m^2] and ``weight_w`` [s^2/rad^2], the diagonal
    of H; the base's ``limits``; ``escape_speed`` [m/s], the most the escape solve may
    move the base along its heading, either way (module docstring); ``lookahead`` l [m]
    of the steering rows' point (not of the barrier, which sits at the axle centre), and
    the headroom the layers above keep beyond the zone (the DWA's rollouts, the re-plan's
    discs and the goal moves treat each circle as ``l`` larger); ``steer_weight`` q
    [s^2/m^4] of the steering rows' slack ``s``."""

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
    steer_weight: float = 200.0
    escape_speed: float = 0.10

    def validate(self) -> list[str]:
        errs = self.limits.validate()
        errs += positive(self, "alpha", "alpha_tight", "lam", "lam_tight", "slack_weight", "weight_v", "weight_w",
                         "lookahead", "steer_weight")
        errs += non_negative(self, "beta", "tight_gap", "escape_speed")
        return errs


class QpStatus(enum.Enum):
    OPTIMAL = "optimal"
    INFEASIBLE = "infeasible"


@dataclass(frozen=True)
class CbfQp:
    """``min 1/2 z^T H z + f^T z`` s.t. ``A z <= b`` and ``lower <= z <= upper``, with
    ``z = (v, w, mu, s)``; row 0 of ``A`` is the CLF (when ``has_clf``), then one barrier
    row per circle (:attr:`cbf_rows`), then, when the base is driven forward, one
    steering row per circle (:attr:`steer_rows`, relaxed by ``s``). ``h`` (k,) the
    barrier values [m^2], ``V`` the CLF value [m^2]."""

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
        start = 1 if self.has_clf else 0
        return slice(start, start + self.h.size)

    @property
    def steer_rows(self) -> slice:
        return slice(self.cbf_rows.stop, self.A.shape[0])


@dataclass(frozen=True)
class CbfResult:
    """The filtered command ``(v, w)`` [m/s, rad/s], the CLF slack ``mu`` [m^2/s],
    ``status``, barrier values ``h`` (k,) [m^2] at the current state (the enforced
    barrier, at the axle centre), ``active`` (k,) True where a circle's barrier or
    steering row binds (non-zero multiplier), the ``alpha`` used (``tight`` when ``alpha_tight``), and
    ``escaped``: the nominal bounds left no safe command and the escape solve's was used."""

    v: float
    w: float
    mu: float
    status: QpStatus
    h: np.ndarray
    active: np.ndarray
    alpha: float
    tight: bool
    V: float
    escaped: bool = False


def _offsets(pose: Pose2D, circles: Circles) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``p - c_i`` (x and y parts) and ``h_i`` at the axle centre of ``pose``."""
    dx = pose.x - circles.centres[:, 0]
    dy = pose.y - circles.centres[:, 1]
    return dx, dy, dx * dx + dy * dy - circles.safety_radii ** 2


def barrier(pose: Pose2D, circles: Circles) -> np.ndarray:
    """The paper's ``h_i = |p - c_i|^2 - r_u,i^2`` [m^2] at the axle centre of ``pose``
    (``r_u``: the circles' safety radii; ``h >= 0``: the footprint at least the margin
    clear of the circle)."""
    return _offsets(pose, circles)[2]


def build_qp(pose: Pose2D, u_ref: tuple[float, float], reference: Pose2D | None, circles: Circles,
             u_prev: tuple[float, float], dt: float, config: CbfConfig, v_cap: float | None = None) -> CbfQp:
    """The QP of one tick: base ``pose`` in ``map``, nominal command ``u_ref``, CLF
    ``reference`` pose (None: no CLF row), obstacle ``circles``, previous command
    ``u_prev`` and tick ``dt`` [s] (for the acceleration bounds), optional forward speed
    cap [m/s]."""
    cfg, lim = config, config.limits
    c, s = math.cos(pose.theta), math.sin(pose.theta)
    gap = np.hypot(circles.centres[:, 0] - pose.x, circles.centres[:, 1] - pose.y) - circles.safety_radii
    tight = int(np.count_nonzero(gap < cfg.tight_gap)) >= 2
    alpha = cfg.alpha_tight if tight else cfg.alpha
    lam = cfg.lam_tight if tight else cfg.lam
    dx, dy, h = _offsets(pose, circles)
    zero = np.zeros_like(h)
    lgh_v = 2.0 * (dx * c + dy * s)  # no w: relative degree 2 in w (module docstring)
    lfh = -2.0 * (dx * circles.velocities[:, 0] + dy * circles.velocities[:, 1])
    rows = [np.stack([-lgh_v, zero, zero, zero], axis=1)]
    rhs = [lfh + alpha * h]
    steer = u_ref[0] > 0.0 and h.size > 0
    if steer:  # the look-ahead point's barrier, relaxed by s (module docstring, "Steering")
        la = cfg.lookahead
        gx, gy = dx + la * c, dy + la * s
        g = gx * gx + gy * gy - (circles.safety_radii + la) ** 2
        lfg = -2.0 * (gx * circles.velocities[:, 0] + gy * circles.velocities[:, 1])
        rows.append(np.stack([-2.0 * (gx * c + gy * s), -2.0 * la * (-gx * s + gy * c), zero, -np.ones_like(h)],
                             axis=1))
        rhs.append(lfg + alpha * g)
    V = 0.0
    if reference is not None:
        ex, ey = reference.x - pose.x, reference.y - pose.y
        dth = math.atan2(math.sin(reference.theta - pose.theta), math.cos(reference.theta - pose.theta))
        delta = abs(dth) / 2.0
        V = 0.5 * (ex * ex + ey * ey) + cfg.beta * math.sin(delta)
        lgv = (-(ex * c + ey * s), -0.5 * cfg.beta * math.cos(delta) * float(np.sign(dth)))
        rows.insert(0, np.array([[lgv[0], lgv[1], -1.0, 0.0]]))
        rhs.insert(0, np.array([-lam * V]))
    v_lo, v_hi, w_lo, w_hi = lim.window(u_prev[0], u_prev[1], dt, v_cap)
    wv, ww = cfg.weight_v, cfg.weight_w
    return CbfQp(
        H=np.diag([2.0 * wv, 2.0 * ww, 2.0 * cfg.slack_weight, 2.0 * cfg.steer_weight]),
        f=np.array([-2.0 * wv * u_ref[0], -2.0 * ww * u_ref[1], 0.0, 0.0]),
        A=np.ascontiguousarray(np.concatenate(rows, axis=0)),
        b=np.concatenate(rhs),
        lower=np.array([v_lo, w_lo, 0.0, 0.0]),
        upper=np.array([v_hi, w_hi, QP_INF, QP_INF if steer else 0.0]),
        has_clf=reference is not None,
        h=h,
        V=V,
        alpha=alpha,
        tight=tight,
    )


def escape_qp(qp: CbfQp, u_prev: tuple[float, float], dt: float, room: tuple[float, float],
              config: CbfConfig) -> CbfQp:
    """The escape solve's QP for the tick whose nominal QP ``qp`` was infeasible, over
    ``z = (v, w, sigma)``: the command closest to standing still (``u_ref = 0``) with
    every barrier row of ``qp`` relaxed by one slack ``sigma >= 0`` [m^2/s] weighted
    :data:`ESCAPE_SLACK_WEIGHT`, so the barriers are kept where any motion can keep them
    and violated as little as the bounds allow where none can (someone already inside
    the zone: ``hdot >= alpha |h|`` may need more than one tick's acceleration); ``v``
    within ``[-room[0], room[1]]`` [m/s] and reachable from ``u_prev`` within ``dt``,
    ``w`` within its window; no CLF row, no steering rows."""
    lim = config.limits
    rows = qp.cbf_rows
    A = qp.A[rows]
    v_lo, v_hi = reachable(u_prev[0], -room[0], room[1], lim.accel_v * dt)
    return CbfQp(
        H=np.diag([2.0 * config.weight_v, 2.0 * config.weight_w, 2.0 * ESCAPE_SLACK_WEIGHT]),
        f=np.zeros(3),
        A=np.ascontiguousarray(np.column_stack([A[:, :2], -np.ones(A.shape[0])])),
        b=qp.b[rows].copy(),
        lower=np.array([v_lo, qp.lower[1], 0.0]),
        upper=np.array([v_hi, qp.upper[1], QP_INF]),
        has_clf=False,
        h=qp.h,
        V=qp.V,
        alpha=qp.alpha,
        tight=qp.tight,
    )


def solve_qp(qp: CbfQp) -> tuple[np.ndarray, QpStatus, np.ndarray]:
    """Solve with DAQP: the minimiser ``z``, the status, and the multipliers of the rows
    of ``A`` (>= 0; 0 for inactive rows). ``z`` is nan when infeasible."""
    m, n = qp.A.shape
    bupper = np.concatenate([qp.upper, qp.b])
    blower = np.concatenate([qp.lower, np.full(m, -QP_INF)])
    sense = np.zeros(n + m, dtype=np.int32)
    z, _, flag, info = daqp.solve(qp.H, qp.f, qp.A, bupper, blower, sense)
    if flag in (1, 2):
        return np.asarray(z, dtype=float), QpStatus.OPTIMAL, np.asarray(info["lam"], dtype=float)[n:]
    if flag != -1:
        log.warning("DAQP ended with exit flag %d (not optimal, not infeasible); treating as infeasible", flag)
    return np.full(n, np.nan), QpStatus.INFEASIBLE, np.zeros(m)


class CbfFilter:
    """The safety filter; stateless apart from its configuration."""

    def __init__(self, config: CbfConfig | None = None) -> None:
        self.config = checked(config or CbfConfig())

    def filter(self, pose: Pose2D, u_ref: tuple[float, float], reference: Pose2D | None, circles: Circles,
               u_prev: tuple[float, float], dt: float, v_cap: float | None = None,
               room: tuple[float, float] = (0.0, 0.0)) -> CbfResult:
        """The command closest to ``u_ref`` (in the H metric) that meets every barrier and
        the bounds, tracking ``reference`` as far as the slack allows; see :func:`build_qp`.
        When that QP is infeasible and the caller measured room to move (``room = (back,
        ahead)``: the speeds [m/s] from which the base can still stop in the room behind
        and ahead; module docstring), the escape solve's command (:func:`escape_qp`, ``v``
        also within ``+-escape_speed``; ``escaped``), reported INFEASIBLE when even that
        cannot keep every barrier. Without room the command brakes at full deceleration
        from ``u_prev`` (INFEASIBLE)."""
        qp = build_qp(pose, u_ref, reference, circles, u_prev, dt, self.config, v_cap)
        z, status, lam = solve_qp(qp)
        if status is QpStatus.OPTIMAL:
            active = lam[qp.cbf_rows] > 1e-9
            if qp.steer_rows.stop > qp.steer_rows.start:
                active |= lam[qp.steer_rows] > 1e-9
            return CbfResult(float(z[0]), float(z[1]), float(z[2]), status, qp.h, active, qp.alpha, qp.tight, qp.V)
        e = self.config.escape_speed
        back, ahead = min(e, max(0.0, room[0])), min(e, max(0.0, room[1]))
        if back + ahead > 0.0:
            eq = escape_qp(qp, u_prev, dt, (back, ahead), self.config)
            z, st, lam = solve_qp(eq)
            if st is QpStatus.OPTIMAL:  # (always, but for a solver failure)
                kept = QpStatus.OPTIMAL if z[2] <= ESCAPE_KEPT else QpStatus.INFEASIBLE
                return CbfResult(float(z[0]), float(z[1]), 0.0, kept, qp.h, lam > 1e-9, qp.alpha, qp.tight,
                                 qp.V, True)
        v, w = self.config.limits.brake(u_prev[0], u_prev[1], dt)
        log.debug("CBF QP infeasible at (%.2f, %.2f, %.2f), min h %.3f m^2: braking", pose.x, pose.y,
                    pose.theta, float(qp.h.min()) if qp.h.size else math.nan)
        return CbfResult(v, w, 0.0, status, qp.h, np.zeros(qp.h.shape, dtype=bool), qp.alpha, qp.tight, qp.V)
