"""Inverse kinematics for many targets at once (numpy arrays over the batch).

The same damped least squares as :meth:`ArmKinematics.ik
<mmexec.skills.manipulation.kinematics.ArmKinematics.ik>` (PoE forward kinematics and
space Jacobian, position error plus a weighted rotation error, the full rotation or only
the approach axis, damping growing with the error, steps capped at 0.4 rad, joints
clamped into their limits), run for a batch of ``B`` targets and starts together: every
iteration is a handful of (B, 3, 3) and (B, 6, 6) array operations instead of ``B``
Python loops. The holistic planner tries hundreds of base poses per query, each with its
own target in the arm base frame; one batch costs about what a few single solves do.

Frames: targets are ``T_armbase_tool`` (B, 4, 4); joints [rad] in the chain's order.
"""

from __future__ import annotations

import numpy as np

from mmexec.skills.manipulation.kinematics import ArmKinematics

__all__ = ["batch_fk", "batch_ik"]

#: [m per rad] weight of the rotation error against the position error (as the single IK)
W_ROT = 0.25


def _skew_rows(w: np.ndarray) -> np.ndarray:
    """(B, 3, 3) skew matrices of (B, 3) vectors."""
    S = np.zeros((w.shape[0], 3, 3))
    S[:, 0, 1], S[:, 0, 2], S[:, 1, 2] = -w[:, 2], w[:, 1], -w[:, 0]
    S[:, 1, 0], S[:, 2, 0], S[:, 2, 1] = w[:, 2], -w[:, 1], w[:, 0]
    return S


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross products of (B, 3) arrays (np.cross's axis handling costs more
    than the products at these sizes)."""
    out = np.empty_like(a)
    out[:, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    out[:, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    out[:, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    return out


_EYE3 = np.eye(3)


def _screw_terms(kin: ArmKinematics) -> list[tuple[np.ndarray, ...]]:
    """Per joint: omega, v, [omega], [omega]^2, [omega] v, [omega]^2 v (cached on ``kin``)."""
    cache = kin.__dict__.get("_batch_terms")
    if cache is None:
        cache = []
        for i in range(kin.dof):
            w, v = kin.screws[:3, i].copy(), kin.screws[3:, i].copy()
            W = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
            cache.append((w, v, W, W @ W, W @ v, W @ W @ v))
        object.__setattr__(kin, "_batch_terms", cache)
    return cache


def batch_fk(kin: ArmKinematics, Q: np.ndarray, jacobian: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Tool rotations (B, 3, 3), positions (B, 3) and space Jacobians (B, 6, n) (rows
    omega then v; None without ``jacobian``) at joint rows ``Q`` (B, n)."""
    B, n = Q.shape
    R = np.broadcast_to(np.eye(3), (B, 3, 3)).copy()
    p = np.zeros((B, 3))
    J = np.zeros((B, 6, n)) if jacobian else None
    for i, (w, v, W, W2, Wv, W2v) in enumerate(_screw_terms(kin)):
        th = Q[:, i]
        if J is not None:
            wi = R @ w
            J[:, :3, i] = wi
            J[:, 3:, i] = _cross(p, wi) + R @ v
        s, c = np.sin(th), np.cos(th)
        Ri = _EYE3 + s[:, None, None] * W + (1.0 - c)[:, None, None] * W2
        pi = th[:, None] * v + (1.0 - c)[:, None] * Wv + (th - s)[:, None] * W2v
        p = (R @ pi[:, :, None])[:, :, 0] + p
        R = R @ Ri
    M = kin.M
    return R @ M[:3, :3], np.einsum("bij,j->bi", R, M[:3, 3]) + p, J


def _log_rotations(R: np.ndarray) -> np.ndarray:
    """Rotation vectors (B, 3) [rad] of rotations (B, 3, 3), as
    :func:`~mmexec.skills.manipulation.kinematics.log_so3` for each."""
    tr = np.einsum("bii->b", R)
    ang = np.arccos(np.clip((tr - 1.0) / 2.0, -1.0, 1.0))
    vee = np.stack([R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]], 1)
    s = np.sin(ang)
    out = np.where((ang < 1e-9)[:, None], vee / 2.0, vee / (2.0 * np.where(s > 1e-12, s, 1.0))[:, None] * ang[:, None])
    near_pi = np.pi - ang < 1e-6
    if near_pi.any():  # the axis from the symmetric part
        Bm = (R[near_pi] + np.eye(3)) / 2.0
        d = np.sqrt(np.clip(np.einsum("bii->bi", Bm), 0.0, None))
        k = np.argmax(d, axis=1)
        axis = Bm[np.arange(len(k)), :, k] / np.sqrt(np.maximum(Bm[np.arange(len(k)), k, k], 1e-12))[:, None]
        out[near_pi] = axis / np.linalg.norm(axis, axis=1)[:, None] * ang[near_pi][:, None]
    return out


def batch_ik(kin: ArmKinematics, T_targets: np.ndarray, Q0: np.ndarray, *, free_approach_rotation: bool = False,
             max_iterations: int = 100, position_tolerance: float = 5e-4,
             rotation_tolerance: float = 5e-3) -> tuple[np.ndarray, np.ndarray]:
    """Solve ``T_targets`` (B, 4, 4) from the starts ``Q0`` (B, n): the joint rows
    (B, n) [rad] and a (B,) mask of the rows that converged within the tolerances [m,
    rad] (inside the joint limits by construction). ``free_approach_rotation``: only the
    approach axis must match. Rows whose target lies beyond the arm's reach are not
    iterated (never converged)."""
    T_targets = np.asarray(T_targets, dtype=float)
    q = np.clip(np.asarray(Q0, dtype=float).copy(), kin.lower, kin.upper)
    B = q.shape[0]
    p_t, R_t = T_targets[:, :3, 3], T_targets[:, :3, :3]
    axis = kin.approach_axis
    a_t = R_t[:, :, axis]
    w0, v0 = kin.screws[:3, 0], kin.screws[3:, 0]
    shoulder = np.cross(w0, v0)
    done = np.zeros(B, dtype=bool)
    active = np.linalg.norm(p_t - shoulder, axis=1) <= kin.reach
    best = np.full(B, np.inf)
    stall = np.zeros(B, dtype=np.int64)
    eye6 = np.eye(6)
    for _ in range(max_iterations):
        idx = np.flatnonzero(active & ~done)
        if idx.size == 0:
            break
        qa = q[idx]
        R, p, J = batch_fk(kin, qa)
        assert J is not None
        e_p = p_t[idx] - p
        Jw, Jv = J[:, :3], J[:, 3:]
        Jp = Jv - _skew_rows(p) @ Jw
        if free_approach_rotation:
            a = R[:, :, axis]
            cr = _cross(a, a_t[idx])
            sn = np.linalg.norm(cr, axis=1)
            ang = np.arctan2(sn, np.einsum("bi,bi->b", a, a_t[idx]))
            e_r = np.where((sn > 1e-12)[:, None], cr / np.where(sn > 1e-12, sn, 1.0)[:, None] * ang[:, None], 0.0)
            flip = (sn <= 1e-12) & (ang > 1.0)  # anti-parallel: any perpendicular axis
            if flip.any():
                ref = np.where((np.abs(a[flip, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
                perp = _cross(a[flip], ref)
                e_r[flip] = perp / np.linalg.norm(perp, axis=1)[:, None] * ang[flip][:, None]
            P = np.eye(3) - a[:, :, None] * a[:, None, :]
            Jr = P @ Jw
        else:
            e_r = _log_rotations(R_t[idx] @ np.transpose(R, (0, 2, 1)))
            Jr = Jw
        conv = (np.linalg.norm(e_p, axis=1) < position_tolerance) & (np.linalg.norm(e_r, axis=1) < rotation_tolerance)
        done[idx[conv]] = True
        go = ~conv
        if not go.any():
            break
        idx, e_p, e_r, Jp, Jr, qa = idx[go], e_p[go], e_r[go], Jp[go], Jr[go], qa[go]
        Jm = np.concatenate([Jp, W_ROT * Jr], axis=1)
        e = np.concatenate([e_p, W_ROT * e_r], axis=1)
        err = np.linalg.norm(e, axis=1)
        better = err < best[idx] * 0.98
        best[idx[better]] = err[better]
        stall[idx] = np.where(better, 0, stall[idx] + 1)
        active[idx[stall[idx] > 12]] = False  # stuck (a joint limit, a singularity): as the single IK
        lam2 = 1e-4 + 0.01 * np.minimum(1.0, err)
        A = Jm @ np.transpose(Jm, (0, 2, 1)) + lam2[:, None, None] * eye6
        dq = np.einsum("bji,bj->bi", Jm, np.linalg.solve(A, e[:, :, None])[:, :, 0])
        m = np.max(np.abs(dq), axis=1)
        dq *= np.where(m > 0.4, 0.4 / np.maximum(m, 1e-12), 1.0)[:, None]
        q[idx] = np.clip(qa + dq, kin.lower, kin.upper)
    return q, done
