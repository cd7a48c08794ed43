"""CLF-CBF QP safety filter: Lie derivatives, the QP against a second solver and a grid,
relaxation, active barriers, the paper's barrier at the axle centre, alpha's meaning,
the escape (a bounded reverse) and infeasibility."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import quadprog

from mmexec.drivers.interfaces import Pose2D
from mmexec.skills.navigation.cbf import (
    CbfConfig,
    CbfFilter,
    QpStatus,
    barrier,
    build_qp,
    escape_qp,
    solve_qp,
)
from mmexec.skills.navigation.limits import BaseLimits
from mmexec.skills.navigation.obstacles import Circles

LIM = BaseLimits(radius=0.178, max_v=0.7, min_v=-0.2, max_w=math.pi, accel_v=1.0, accel_w=3.5)
CFG = CbfConfig(limits=LIM)


def _circles(centres, safety, velocities=None):
    c = np.asarray(centres, dtype=float).reshape(-1, 2)
    n = c.shape[0]
    s = np.broadcast_to(np.asarray(safety, dtype=float), (n,)).copy()
    v = np.zeros((n, 2)) if velocities is None else np.asarray(velocities, dtype=float).reshape(-1, 2)
    return Circles(c, s - 0.228, s, v, np.arange(n), np.zeros(n, dtype=bool))


def _quadprog(qp):
    """The same QP with quadprog (Goldfarb-Idnani dual active set): z or None if infeasible."""
    n = qp.H.shape[0]
    rows = [-qp.A, np.eye(n)]
    rhs = [-qp.b, qp.lower]
    finite = qp.upper < 1e29
    rows.append(-np.eye(n)[finite])
    rhs.append(-qp.upper[finite])
    C = np.vstack(rows).T
    try:
        return quadprog.solve_qp(qp.H, -qp.f, C, np.concatenate(rhs))[0]
    except ValueError as e:
        assert "inconsistent" in str(e)
        return None


def _random_instance(rng, n_max=4):
    pose = Pose2D(*rng.uniform(-1, 1, 2), rng.uniform(-math.pi, math.pi))
    k = int(rng.integers(0, n_max + 1))
    ang = rng.uniform(-math.pi, math.pi, k)
    dist = rng.uniform(0.35, 2.0, k)
    centres = np.column_stack([pose.x + dist * np.cos(ang), pose.y + dist * np.sin(ang)])
    vel = rng.normal(0, 0.4, (k, 2)) * (rng.random((k, 1)) < 0.5)
    circles = _circles(centres, rng.uniform(0.25, 0.6, k), vel)
    u_ref = (rng.uniform(LIM.min_v, LIM.max_v), rng.uniform(-LIM.max_w, LIM.max_w))
    u_prev = (rng.uniform(LIM.min_v, LIM.max_v), rng.uniform(-LIM.max_w, LIM.max_w))
    ref = None if rng.random() < 0.2 else Pose2D(pose.x + rng.normal(0, 0.6), pose.y + rng.normal(0, 0.6),
                                                  rng.uniform(-math.pi, math.pi))
    dt = float(rng.choice([0.05, 0.2, 1.0]))
    cfg = replace(CFG, alpha=float(rng.choice([0.21, 0.46, 2.0])))
    return build_qp(pose, u_ref, ref, circles, u_prev, dt, cfg)


def test_qp_matches_quadprog_on_random_instances():
    rng = np.random.default_rng(12)
    kinds = {"infeasible": 0, "barrier active": 0, "clf relaxed": 0, "interior": 0}
    worst = 0.0
    for _ in range(3000):
        qp = _random_instance(rng)
        z, status, lam = solve_qp(qp)
        ref = _quadprog(qp)
        if ref is None:
            assert status is QpStatus.INFEASIBLE
            kinds["infeasible"] += 1
            continue
        assert status is QpStatus.OPTIMAL
        worst = max(worst, float(np.max(np.abs(z - ref))))
        if (lam[qp.cbf_rows] > 1e-9).any():
            kinds["barrier active"] += 1
        if z[2] > 1e-9:
            kinds["clf relaxed"] += 1
        if not (lam > 1e-9).any() and z[2] <= 1e-9:
            kinds["interior"] += 1
    assert worst < 1e-6
    assert min(kinds.values()) >= 50, kinds


def test_the_escape_qp_matches_quadprog_and_is_always_feasible():
    rng = np.random.default_rng(21)
    worst, moved = 0.0, 0
    for _ in range(1000):
        qp = _random_instance(rng)
        room = tuple(rng.uniform(0.0, 0.1, 2))
        eq = escape_qp(qp, (rng.uniform(-0.1, 0.1), 0.0), 0.05, room, CFG)
        z, status, _ = solve_qp(eq)
        assert status is QpStatus.OPTIMAL
        assert -room[0] - 1e-9 <= z[0] <= room[1] + 1e-9 or abs(z[0]) <= 0.1 + 1e-9
        worst = max(worst, float(np.max(np.abs(z - _quadprog(eq)))))
        moved += abs(z[0]) > 1e-6
    assert worst < 1e-6 and moved > 100


def _grid_optimum(qp, n=301):
    """Brute force on a (v, w) grid over the box; mu and s at their least feasible values."""
    v = np.linspace(qp.lower[0], qp.upper[0], n)
    w = np.linspace(qp.lower[1], qp.upper[1], n)
    vv, ww = np.meshgrid(v, w, indexing="ij")
    u = np.stack([vv.ravel(), ww.ravel()], axis=1)
    rows = qp.cbf_rows
    ok = np.all(u @ qp.A[rows, :2].T <= qp.b[rows] + 1e-12, axis=1)
    mu = np.maximum(0.0, u @ qp.A[0, :2] - qp.b[0]) if qp.has_clf else np.zeros(len(u))
    st = qp.steer_rows
    s = np.maximum(0.0, (u @ qp.A[st, :2].T - qp.b[st]).max(axis=1)) if st.stop > st.start else np.zeros(len(u))
    z = np.column_stack([u, mu, s])
    cost = 0.5 * ((z @ qp.H) * z).sum(axis=1) + z @ qp.f
    if not ok.any():
        return None, math.inf, (v[1] - v[0], w[1] - w[0])
    i = int(np.argmin(np.where(ok, cost, np.inf)))
    return z[i], float(cost[i]), (v[1] - v[0], w[1] - w[0])


def test_qp_matches_a_brute_force_grid_on_small_instances():
    """No grid point beats the solver, and the grid's best point lies where strong
    convexity says it must: (m / 2) |u_g - u*|^2 <= cost_g - cost* with m the smallest
    eigenvalue of the Hessian's (v, w) block. Most grid optima are within a few cells."""
    rng = np.random.default_rng(5)
    checked = close = 0
    while checked < 25:
        qp = _random_instance(rng, n_max=2)
        z, status, _ = solve_qp(qp)
        zg, cg, (dv, dw) = _grid_optimum(qp)
        if zg is None:
            continue  # the grid found no feasible point: the feasible set is empty or thin
        assert status is QpStatus.OPTIMAL
        rows = qp.cbf_rows
        assert np.all(qp.A[rows] @ z <= qp.b[rows] + 1e-9)
        cost = 0.5 * z @ qp.H @ z + qp.f @ z
        assert cost <= cg + 1e-9
        m = float(np.min(np.diag(qp.H)[:2]))
        assert 0.5 * m * float(np.sum((zg[:2] - z[:2]) ** 2)) <= cg - cost + 1e-9
        close += abs(z[0] - zg[0]) <= 4 * dv and abs(z[1] - zg[1]) <= 4 * dw
        checked += 1
    assert close >= 20


def _moved(pose, u, s):
    """The unicycle ``s`` seconds along ``u`` (first order: enough for a derivative at 0)."""
    return Pose2D(pose.x + u[0] * s * math.cos(pose.theta), pose.y + u[0] * s * math.sin(pose.theta),
                  pose.theta + u[1] * s)


def _h_along(pose, u, c, cv, s, cfg):
    return barrier(_moved(pose, u, s), _circles([np.asarray(c) + cv * s], 0.4))[0]


def _v_along(pose, u, ref, s, cfg):
    p = _moved(pose, u, s)
    d = math.atan2(math.sin(ref.theta - p.theta), math.cos(ref.theta - p.theta))
    return 0.5 * ((ref.x - p.x) ** 2 + (ref.y - p.y) ** 2) + cfg.beta * math.sin(abs(d) / 2)


def test_lie_derivatives_match_finite_differences():
    """hdot = Lfh + Lgh u and Vdot = LgV u along the unicycle flow (moving obstacle: its
    velocity is the drift); checked by a central difference of h and V."""
    rng = np.random.default_rng(7)
    cfg = CFG
    for _ in range(200):
        pose = Pose2D(*rng.uniform(-1, 1, 2), rng.uniform(-math.pi, math.pi))
        c = pose.x + rng.uniform(-2, 2), pose.y + rng.uniform(-2, 2)
        cv = rng.normal(0, 0.5, 2)
        ref = Pose2D(*rng.uniform(-1, 1, 2), rng.uniform(-math.pi, math.pi))
        dth = math.atan2(math.sin(ref.theta - pose.theta), math.cos(ref.theta - pose.theta))
        if abs(dth) < 1e-3 or abs(abs(dth) - math.pi) < 1e-2:
            continue  # |.| has no derivative at 0, the wrap none at pi
        u = rng.uniform(-0.5, 0.5), rng.uniform(-2, 2)
        qp = build_qp(pose, u, ref, _circles([c], 0.4, [cv]), u, 0.05, cfg)
        eps = 1e-6
        hdot = (_h_along(pose, u, c, cv, eps, cfg) - _h_along(pose, u, c, cv, -eps, cfg)) / (2 * eps)
        vdot = (_v_along(pose, u, ref, eps, cfg) - _v_along(pose, u, ref, -eps, cfg)) / (2 * eps)
        # CBF row: -Lgh u <= Lfh + alpha h  ->  Lgh u + Lfh = -(row . u) + (b - alpha h)
        row, b = qp.A[1], qp.b[1]
        assert -(row[:2] @ u) + (b - qp.alpha * qp.h[0]) == pytest.approx(hdot, abs=1e-5)
        # CLF row: LgV u - mu <= -lambda V
        assert qp.A[0, :2] @ u == pytest.approx(vdot, abs=1e-5)
        assert qp.V == pytest.approx(_v_along(pose, u, ref, 0.0, cfg))


def test_the_barrier_is_the_papers_at_the_axle_centre():
    """h = |p - c|^2 - r_u^2 at the axle centre whatever the heading (the look-ahead is
    no part of it), so h >= 0 is exactly the footprint at least the margin clear of the
    circle; its derivative holds no w (relative degree 2)."""
    rng = np.random.default_rng(3)
    for _ in range(500):
        pose = Pose2D(*rng.uniform(-2, 2, 2), rng.uniform(-math.pi, math.pi))
        c = _circles(rng.uniform(-2, 2, (1, 2)), rng.uniform(0.2, 0.8))
        d = math.hypot(pose.x - c.centres[0, 0], pose.y - c.centres[0, 1])
        assert barrier(pose, c)[0] == pytest.approx(d * d - c.safety_radii[0] ** 2)
        turned = Pose2D(pose.x, pose.y, pose.theta + rng.uniform(-3, 3))
        assert barrier(turned, c)[0] == pytest.approx(barrier(pose, c)[0])
        qp = build_qp(pose, (0.3, 0.5), None, c, (0.3, 0.5), 0.05, replace(CFG, lookahead=0.3))
        assert qp.A[0, 1] == 0.0
    # a person 0.3 m from the footprint (the sim's people stop there) is outside the zone
    # with the 5 cm margin, head-on or not
    person = _circles([[0.178 + 0.3 + 0.2, 0.0]], 0.2 + 0.178 + 0.05)
    assert barrier(Pose2D(0.0, 0.0, 0.0), person)[0] > 0


def test_a_safe_command_passes_unchanged():
    pose = Pose2D(0.0, 0.0, 0.0)
    ref = Pose2D(0.3, 0.0, 0.0)                       # straight ahead: driving on decreases V
    f = CbfFilter(CFG).filter(pose, (0.4, 0.0), ref, _circles([[0.0, 3.0]], 0.5), (0.4, 0.0), 0.05)
    assert f.status is QpStatus.OPTIMAL
    assert (f.v, f.w, f.mu) == pytest.approx((0.4, 0.0, 0.0), abs=1e-9)
    assert not f.active.any()


def test_the_clf_is_relaxed_when_it_cannot_be_met():
    """The reference is behind the robot and the box forbids reversing: no (v, w) makes V
    decrease at rate lambda; mu takes up exactly the shortfall, and without mu the QP has
    no solution."""
    lim = replace(LIM, min_v=0.0)
    cfg = replace(CFG, limits=lim)
    pose = Pose2D(0.0, 0.0, 0.0)
    ref = Pose2D(-1.0, 0.0, 0.0)
    qp = build_qp(pose, (0.2, 0.0), ref, Circles(), (0.2, 0.0), 0.05, cfg)
    z, status, lam = solve_qp(qp)
    assert status is QpStatus.OPTIMAL and z[2] > 0.1
    assert z[2] == pytest.approx(qp.A[0, :2] @ z[:2] - qp.b[0])   # CLF row active, mu = shortfall
    assert lam[0] > 0
    np.testing.assert_allclose(z, _quadprog(qp), atol=1e-7)
    assert solve_qp(replace(qp, upper=np.array([qp.upper[0], qp.upper[1], 0.0])))[1] is QpStatus.INFEASIBLE


def test_driving_at_an_obstacle_the_filter_turns_away_within_the_barrier():
    """Straight at a circle: the steering row turns the base (w is cheap), the barrier
    h holds its rate, and the slack s takes up the rest."""
    pose = Pose2D(0.0, 0.0, 0.0)
    circles = _circles([[0.8, 0.4]], 0.5)
    qp = build_qp(pose, (0.3, 0.0), None, circles, (0.3, 0.0), 0.05, CFG)
    z, status, lam = solve_qp(qp)
    assert status is QpStatus.OPTIMAL and qp.steer_rows == slice(1, 2)
    assert z[1] < -0.1                                            # turns away (the circle is to the left)
    assert qp.A[qp.cbf_rows, :2] @ z[:2] <= qp.b[qp.cbf_rows] + 1e-9
    assert lam[qp.steer_rows][0] > 0
    # told to stand, the base gets no steering rows (it is not turned away from people)
    assert build_qp(pose, (0.0, 0.0), None, circles, (0.0, 0.0), 0.05, CFG).steer_rows == slice(1, 1)


def test_a_barrier_binds_when_driving_at_an_obstacle():
    pose = Pose2D(0.0, 0.0, 0.0)
    circles = _circles([[1.0, 0.0]], 0.5)
    cfg = replace(CFG, steer_weight=1e-9)                          # the paper's barrier alone
    f = CbfFilter(cfg).filter(pose, (0.7, 0.0), None, circles, (0.7, 0.0), 1.0)
    assert f.status is QpStatus.OPTIMAL and f.active.tolist() == [True]
    qp = build_qp(pose, (0.7, 0.0), None, circles, (0.7, 0.0), 1.0, cfg)
    # hdot + alpha h = 0 at the solution: the approach is as fast as the barrier allows
    assert qp.A[0, :2] @ np.array([f.v, f.w]) == pytest.approx(qp.b[0], abs=1e-9)
    assert f.v < 0.7


def test_a_larger_alpha_allows_a_faster_approach():
    """The standard condition hdot >= -alpha h: alpha bounds how fast h may fall, so the
    paper's raise from 0.21 to 0.46 lets the base close on an obstacle faster."""
    pose = Pose2D(0.0, 0.0, 0.0)
    circles = _circles([[1.5, 0.0]], 0.5)
    speeds = []
    for alpha in (0.21, 0.46, 1.0):
        f = CbfFilter(replace(CFG, alpha=alpha, steer_weight=1e-9)).filter(pose, (0.7, 0.0), None, circles, (0.7, 0.0), 1.0)
        speeds.append(f.v)
    assert speeds[0] < speeds[1] < speeds[2]
    # straight at the obstacle: v <= alpha h / (2 |p - c|)
    d = 1.5
    h = d * d - 0.5 ** 2
    assert speeds[0] == pytest.approx(0.21 * h / (2 * d), rel=1e-6)


def test_tight_spaces_switch_alpha_and_lambda():
    pose = Pose2D(0.0, 0.0, 0.0)
    one = _circles([[0.0, 0.7]], 0.5)
    two = _circles([[0.0, 0.7], [0.0, -0.7]], 0.5)        # a passage: both gaps 0.2 m
    a = build_qp(pose, (0.3, 0.0), Pose2D(1.0, 0.0, 0.0), one, (0.3, 0.0), 0.05, CFG)
    b = build_qp(pose, (0.3, 0.0), Pose2D(1.0, 0.0, 0.0), two, (0.3, 0.0), 0.05, CFG)
    assert (a.tight, a.alpha) == (False, CFG.alpha)
    assert (b.tight, b.alpha) == (True, CFG.alpha_tight)
    assert b.b[0] == pytest.approx(-CFG.lam_tight * b.V)


def test_an_infeasible_qp_brakes():
    """A person walking fast into a robot that cannot reverse (no room behind): no
    command keeps h from falling faster than alpha allows; the filter reports it and
    brakes."""
    cfg = replace(CFG, limits=replace(LIM, min_v=0.0))
    pose = Pose2D(0.0, 0.0, 0.0)
    circles = _circles([[0.9, 0.0]], 0.5, [[-1.5, 0.0]])
    f = CbfFilter(cfg).filter(pose, (0.3, 0.5), None, circles, (0.3, 0.5), 0.05)
    assert f.status is QpStatus.INFEASIBLE and not f.escaped
    assert (f.v, f.w) == pytest.approx((0.3 - 0.05, 0.5 - 0.175))
    assert _quadprog(build_qp(pose, (0.3, 0.5), None, circles, (0.3, 0.5), 0.05, cfg)) is None


def test_someone_inside_the_zone_is_escaped_from_within_the_room():
    """Someone stepped inside the zone in front of a standing base (h < 0): forward-only,
    no command restores h (braking is infeasible); with room behind, the escape solve
    backs off, no faster than the escape speed or the room allows, and h rises."""
    cfg = replace(CFG, limits=replace(LIM, min_v=0.0))
    pose = Pose2D(0.0, 0.0, 0.0)
    circles = _circles([[0.6, 0.0]], 0.65)                       # h = 0.36 - 0.4225 < 0
    flt = CbfFilter(cfg)
    assert flt.filter(pose, (0.0, 0.0), None, circles, (0.0, 0.0), 0.05).status is QpStatus.INFEASIBLE
    f = flt.filter(pose, (0.0, 0.0), None, circles, (0.0, 0.0), 0.05, room=(1.0, 1.0))
    assert f.escaped
    assert -cfg.escape_speed - 1e-9 <= f.v < 0.0                # backs off, within one tick's acceleration
    assert f.v == pytest.approx(-LIM.accel_v * 0.05)
    assert barrier(_moved(pose, (f.v, f.w), 0.05), circles)[0] > f.h[0]
    assert f.status is QpStatus.INFEASIBLE                      # h cannot rise at rate alpha |h| in one tick
    # once moving: as slow as restores h at rate alpha |h| (hdot = 2 (p - c) . v e_th)
    f = flt.filter(pose, (0.0, 0.0), None, circles, (-0.1, 0.0), 0.05, room=(1.0, 1.0))
    assert f.status is QpStatus.OPTIMAL and f.escaped
    assert f.v == pytest.approx(-cfg.alpha * -f.h[0] / (2 * 0.6), rel=1e-3)
    # never faster than the escape speed, nor than the room allows (one tick's deceleration)
    fast = CbfFilter(replace(cfg, alpha=50.0))
    assert fast.filter(pose, (0.0, 0.0), None, circles, (-0.1, 0.0), 0.05, room=(1.0, 1.0)).v == \
        pytest.approx(-cfg.escape_speed)
    assert fast.filter(pose, (0.0, 0.0), None, circles, (-0.1, 0.0), 0.05, room=(0.04, 1.0)).v == \
        pytest.approx(-0.05)
    # the escape never moves the base towards the circle: with room only ahead, it brakes
    f = flt.filter(pose, (0.0, 0.0), None, circles, (0.0, 0.0), 0.05, room=(0.0, 1.0))
    assert f.status is QpStatus.INFEASIBLE and (f.v, f.w) == (0.0, 0.0)
    # someone walking into the side of the base: moving along the heading does not help
    side = _circles([[0.0, 0.6]], 0.5, [[0.0, -1.0]])
    f = flt.filter(pose, (0.0, 0.0), None, side, (0.0, 0.0), 0.05, room=(1.0, 1.0))
    assert f.status is QpStatus.INFEASIBLE


def test_cbf_config_validation():
    assert CbfConfig().validate() == []
    with pytest.raises(ValueError, match="CbfConfig: alpha"):
        CbfFilter(CbfConfig(alpha=0.0))
