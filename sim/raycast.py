"""Closest hits of a batch of rays in a pybullet client, solved in closed form where the
geometry allows it.

pybullet's ``rayTestBatch`` finds each ray's hit on a convex shape by an iterative convex
cast (GJK), a few microseconds per ray and shape near it, so the 400 beams of a lidar scan
in the ``lab`` cost about 2 ms, most of a local-planner trial's wall time. The fixed
parts of a world and its people are boxes, upright cylinders and the floor plane, whose
ray intersections have closed forms: :class:`SceneRays` solves those for all rays at
once with numpy and hands only the rays that can reach anything else (items, the robot's
own links, plants, panels: any body or shape not solved here, found by their bounding
boxes) to ``rayTestBatch``, whose answers for those rays are kept whole.

The closed forms are exact; Bullet's cast stops within its tolerance (a beam's range
moves by up to 0.4 mm with the beam's length alone), so a range differs from pybullet's
by less than 1 mm in 99 % of beams (more where a beam grazes a surface: a millimetre
across the beam is centimetres along it), and a beam grazing an edge or a person within
that tolerance (about 0.1 % of beams) may hit on one side and miss on the other.
tests/sim/test_raycast.py compares the two over the shipped worlds.

Frames: ``map`` (pybullet's world frame); metres.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np
import pybullet as p

__all__ = ["RayHits", "SceneRays"]

#: [m] slack on the bounding boxes that decide which rays pybullet casts
_AABB_SLACK = 1e-3


@dataclass(frozen=True)
class RayHits:
    """Per ray: hit ``fraction`` of the ray's length (``inf``: no hit), ``body`` and
    ``link`` hit (-1, -1: none), unit ``normal`` of the surface in ``map`` (zero: none),
    and how many rays pybullet cast (``cast``)."""

    fraction: np.ndarray
    body: np.ndarray
    link: np.ndarray
    normal: np.ndarray
    cast: int


def _pose(pos: Iterable[float], quat: Iterable[float]) -> tuple[np.ndarray, np.ndarray]:
    return np.array(p.getMatrixFromQuaternion(list(quat))).reshape(3, 3), np.array(list(pos), dtype=float)


def _compose(a: tuple[np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    return a[0] @ b[0], a[0] @ b[1] + a[1]


class _Prims:
    """Boxes (half extents), cylinders (radius, half height, axis local z) and planes
    (normal, offset) with their ``(body, link)`` and pose ``R`` (world from shape),
    ``c`` (shape origin in world)."""

    def __init__(self) -> None:
        self.kind: list[str] = []
        self.size: list[tuple[float, float, float]] = []
        self.ids: list[tuple[int, int]] = []
        self.R: list[np.ndarray] = []
        self.c: list[np.ndarray] = []

    def add(self, kind: str, size: tuple[float, float, float], ids: tuple[int, int],
            pose: tuple[np.ndarray, np.ndarray]) -> None:
        self.kind.append(kind)
        self.size.append(size)
        self.ids.append(ids)
        self.R.append(pose[0])
        self.c.append(pose[1])


def _link_shapes(cid: int, body: int, link: int) -> list[tuple[str, tuple[float, float, float], tuple[np.ndarray, np.ndarray]]] | None:
    """The link's collision shapes as ``(kind, size, pose of the shape in the link's
    inertial frame)``; None when one of them has no closed form here (a mesh, a sphere)."""
    out = []
    for shape in p.getCollisionShapeData(body, link, physicsClientId=cid):
        geom, dims, lpos, lorn = shape[2], shape[3], shape[5], shape[6]
        local = _pose(lpos, lorn)
        if geom == p.GEOM_BOX:
            out.append(("box", (dims[0] / 2, dims[1] / 2, dims[2] / 2), local))
        elif geom == p.GEOM_CYLINDER:
            out.append(("cyl", (dims[1], dims[0] / 2, 0.0), local))
        elif geom == p.GEOM_PLANE:
            out.append(("plane", (dims[0], dims[1], dims[2]), local))
        else:
            return None
    return out


def _frame(cid: int, body: int, link: int) -> tuple[np.ndarray, np.ndarray]:
    """World pose of a link's inertial frame (the frame collision shapes are given in)."""
    if link < 0:
        return _pose(*p.getBasePositionAndOrientation(body, physicsClientId=cid))
    s = p.getLinkState(body, link, physicsClientId=cid)
    return _pose(s[0], s[1])


class SceneRays:
    """Ray casts in client ``cid`` with ``fixed`` bodies (never moved: their shapes are
    read once) and ``moving`` single-link bodies (people: their pose is read at each cast)
    solved in closed form where their shapes allow; every other body, and any link of
    theirs with another shape, is left to pybullet."""

    def __init__(self, cid: int, fixed: Iterable[int], moving: Iterable[int] = ()) -> None:
        self._cid = cid
        self._fixed = _Prims()
        self._pybullet_links: set[tuple[int, int]] = set()
        for body in fixed:
            for link in range(-1, p.getNumJoints(body, physicsClientId=cid)):
                shapes = _link_shapes(cid, body, link)
                if shapes is None:
                    self._pybullet_links.add((body, link))
                    continue
                if shapes:
                    frame = _frame(cid, body, link)
                    for kind, size, local in shapes:
                        self._fixed.add(kind, size, (body, link), _compose(frame, local))
        self._moving: list[tuple[int, list[tuple[str, tuple[float, float, float], tuple[np.ndarray, np.ndarray]]]]] = []
        for body in moving:
            shapes = _link_shapes(cid, body, -1)
            if shapes is None or p.getNumJoints(body, physicsClientId=cid) > 0:
                self._pybullet_links.add((body, -1))
            else:
                self._moving.append((body, shapes))
        self._closed = {b for b in fixed} | {b for b, _ in self._moving}
        #: the moving bodies' shapes in their frames, by kind: (body index, R, c, size, ids)
        self._moving_local: dict[str, tuple[np.ndarray, ...]] = {}
        for kind in ("box", "cyl", "plane"):
            rows = [(i, size, local, b) for i, (b, shapes) in enumerate(self._moving)
                    for k, size, local in shapes if k == kind]
            if rows:
                self._moving_local[kind] = (np.array([r[0] for r in rows]), np.array([r[2][0] for r in rows]),
                                            np.array([r[2][1] for r in rows]), np.array([r[1] for r in rows]),
                                            np.array([(r[3], -1) for r in rows]))
        self._others: list[tuple[int, int]] = []
        self._n_bodies: tuple[int, int] = (-1, -1)
        self._arrays = self._stack(self._fixed)
        #: the fixed shapes a level scan at height z cuts, by z (a lidar keeps its height)
        self._levels: dict[float, dict[str, tuple[np.ndarray, ...]]] = {}

    @staticmethod
    def _stack(prims: _Prims) -> dict[str, tuple[np.ndarray, ...]]:
        out: dict[str, tuple[np.ndarray, ...]] = {}
        for kind in ("box", "cyl", "plane"):
            idx = [i for i, k in enumerate(prims.kind) if k == kind]
            if idx:
                out[kind] = (np.array([prims.R[i] for i in idx]), np.array([prims.c[i] for i in idx]),
                             np.array([prims.size[i] for i in idx]), np.array([prims.ids[i] for i in idx]))
        return out

    @staticmethod
    def _cut(arrays: dict[str, tuple[np.ndarray, ...]], z: float) -> dict[str, tuple[np.ndarray, ...]]:
        """The upright boxes and cylinders of ``arrays`` that span height ``z`` (as
        rectangles and circles: ``rect``, ``circle``), and all the other shapes (by kind)."""
        out: dict[str, tuple[np.ndarray, ...]] = {}
        for kind, (R, c, size, ids) in arrays.items():
            if kind == "plane":  # a level scan never meets a level plane
                keep = np.flatnonzero(np.abs((R @ size[:, :, None])[:, 2, 0]) != 1.0)
            else:  # boxes and cylinders
                upright = np.abs(R[:, 2, 2]) == 1.0
                cut = np.flatnonzero(upright & (np.abs(z - c[:, 2]) <= size[:, 2 if kind == "box" else 1]))
                if cut.size:
                    out[_PLANAR_NAME[kind]] = (R[cut], c[cut], size[cut], ids[cut])
                keep = np.flatnonzero(~upright)
            if keep.size:
                out[kind] = (R[keep], c[keep], size[keep], ids[keep])
        if "rect" in out:  # rectangle corners, for the bearing ranges
            R, c, half, _ = out["rect"]
            ux, uy = R[:, :2, 0] * half[:, 0:1], R[:, :2, 1] * half[:, 1:2]
            corners = c[:, None, :2] + np.stack([ux + uy, ux - uy, -ux - uy, -ux + uy], axis=1)
            out["rect"] = (*out["rect"], corners)
        return out

    def _moving_arrays(self) -> dict[str, tuple[np.ndarray, ...]]:
        """The moving bodies' shapes where they are now."""
        cid = self._cid
        poses = [p.getBasePositionAndOrientation(b, physicsClientId=cid) for b, _ in self._moving]
        pos = np.array([q[0] for q in poses])
        rot = np.array([np.eye(3) if q[1] == (0.0, 0.0, 0.0, 1.0) else
                        np.array(p.getMatrixFromQuaternion(q[1])).reshape(3, 3) for q in poses])
        out = {}
        for kind, (which, R, c, size, ids) in self._moving_local.items():
            Rb = rot[which]
            out[kind] = (Rb @ R, np.einsum("kij,kj->ki", Rb, c) + pos[which], size, ids)
        return out

    def _other_links(self) -> list[tuple[int, int]]:
        """Every (body, link) pybullet has to cast against (refreshed when bodies come or go:
        body ids only grow, so the count and the newest id tell)."""
        cid = self._cid
        n = p.getNumBodies(physicsClientId=cid)
        key = (n, p.getBodyUniqueId(n - 1, physicsClientId=cid) if n else -1)
        if key != self._n_bodies:
            others = []
            for k in range(n):
                body = p.getBodyUniqueId(k, physicsClientId=cid)
                if body not in self._closed:  # links without a collision shape are never hit
                    others += [(body, li) for li in range(-1, p.getNumJoints(body, physicsClientId=cid))
                               if p.getCollisionShapeData(body, li, physicsClientId=cid)]
            self._others = others + sorted(self._pybullet_links)
            self._n_bodies = key
        return self._others

    def cast(self, starts: np.ndarray, ends: np.ndarray, dirs: np.ndarray, length: float,
             origin: np.ndarray | None = None) -> RayHits:
        """Closest hit of each ray from ``starts`` (N, 3) to ``ends`` (N, 3), along unit
        ``dirs`` (N, 3), ``length`` [m] long (pybullet casts ``starts`` to ``ends``).
        ``origin``: a point (3,) every ray's line passes through behind its start (a
        lidar's centre), which lets a level scan test each shape against the rays of its
        bearings only."""
        n = len(starts)
        best = np.full(n, np.inf)
        body = np.full(n, -1, dtype=np.int64)
        link = np.full(n, -1, dtype=np.int64)
        normal = np.zeros((n, 3))
        moving = self._moving_arrays() if self._moving else {}
        # a level scan (every ray horizontal, from one height): upright boxes and cylinders
        # that span that height are rectangles and circles in the scan's plane
        planar = not dirs[:, 2].any() and bool(np.all(starts[:, 2] == starts[0, 2]))
        if planar:
            z = float(starts[0, 2])
            if z not in self._levels:
                self._levels[z] = self._cut(self._arrays, z)
            groups = dict(self._levels[z])
            for kind, arr in self._cut(moving, z).items():
                groups[kind] = tuple(np.concatenate([x, y]) for x, y in zip(groups[kind], arr)) if kind in groups else arr
        else:
            groups = dict(self._arrays)
            for kind, arr in moving.items():
                groups[kind] = tuple(np.concatenate([x, y]) for x, y in zip(groups[kind], arr)) if kind in groups else arr
        sorted_bearings = None
        if planar and origin is not None:
            bear = np.arctan2(dirs[:, 1], dirs[:, 0])
            order = np.argsort(bear, kind="stable")
            sorted_bearings = (bear[order], order)
        pairs: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
        for kind, (R, c, size, ids, *extra) in groups.items():
            if kind in _HITS:
                self._closest(_HITS[kind](starts, dirs, R, c, size), ids, length, best, body, link, normal)
                continue
            kernel, extent = _LEVEL[kind]
            if sorted_bearings is not None:
                k, ray = _sector_pairs(sorted_bearings, *extent(origin, R, c, size, *extra))
            else:
                k, ray = np.divmod(np.arange(len(ids) * n), n)
            t, nrm = kernel(starts, dirs, R, c, size, k, ray)
            hit = t <= length
            pairs.append((t[hit], ray[hit], ids[k[hit]], nrm[hit]))
        t = np.concatenate([x[0] for x in pairs]) if pairs else np.zeros(0)
        if t.size:
            ray, pid, nrm = (np.concatenate(x) for x in list(zip(*pairs))[1:])
            order = np.lexsort((t, ray))  # by ray, nearest first
            ray_o = ray[order]
            first = order[np.flatnonzero(np.r_[True, ray_o[1:] != ray_o[:-1]])]
            better = first[t[first] < best[ray[first]]]
            rows = ray[better]
            best[rows] = t[better]
            body[rows], link[rows] = pid[better, 0], pid[better, 1]
            normal[rows] = nrm[better]
        return self._others_cast(starts, ends, dirs, length, planar, best, body, link, normal)

    @staticmethod
    def _closest(hits: tuple[np.ndarray, Callable[[np.ndarray, np.ndarray], np.ndarray]], ids: np.ndarray, length: float,
                 best: np.ndarray, body: np.ndarray, link: np.ndarray, normal: np.ndarray) -> None:
        """Fold one group of shapes' hits ``(t (K, N), normal(k, rows))`` into the closest
        hits so far (in place)."""
        t, nrm = hits
        t[t > length] = np.inf
        k = np.argmin(t, axis=0)
        tk = t[k, np.arange(len(best))]
        rows = np.flatnonzero(tk < best)
        if rows.size:
            best[rows] = tk[rows]
            body[rows], link[rows] = ids[k[rows], 0], ids[k[rows], 1]
            normal[rows] = nrm(k[rows], rows)

    def _others_cast(self, starts: np.ndarray, ends: np.ndarray, dirs: np.ndarray, length: float, planar: bool,
                     best: np.ndarray, body: np.ndarray, link: np.ndarray, normal: np.ndarray) -> RayHits:
        """The closed-form hits, with pybullet's answers for the rays that may reach
        anything else first."""
        n = len(best)
        # rays whose way to their closed-form hit crosses the bounding box of anything else
        reach = np.minimum(best, length) + _AABB_SLACK
        span = reach
        boxes = [p.getAABB(b, li, physicsClientId=self._cid) for b, li in self._other_links()]
        cast = np.zeros(n, dtype=bool)
        if boxes:
            lo = np.array([b[0] for b in boxes]) - _AABB_SLACK
            hi = np.array([b[1] for b in boxes]) + _AABB_SLACK
            if planar:  # only the boxes the scan's plane cuts, as rectangles
                z = starts[0, 2]
                cut = (lo[:, 2] <= z) & (z <= hi[:, 2])
                lo, hi = lo[cut], hi[cut]
            t_in, t_out = _aabb_span(starts, dirs, lo, hi, 2 if planar else 3)
            crossed = t_in <= reach[None, :]
            cast = np.any(crossed, axis=0)
            # past the last box it crosses, a ray meets only closed-form shapes
            span = np.minimum(reach, np.max(np.where(crossed, t_out, 0.0), axis=0) + _AABB_SLACK)
        rows = np.flatnonzero(cast)
        frac = best / length
        if rows.size:
            # pybullet casts only as far as the closed-form hit or past the last box the ray
            # crosses, whichever is nearer (its cost grows with what a ray passes): a hit
            # it finds is the nearest, none leaves the closed-form one
            full = span[rows] >= length
            spans = np.where(full, length, span[rows])
            stops = np.where(full[:, None], ends[rows], starts[rows] + dirs[rows] * spans[:, None])
            hits = p.rayTestBatch(starts[rows].tolist(), stops.tolist(), numThreads=0, physicsClientId=self._cid)
            for r, h, sp in zip(rows, hits, spans):
                if h[0] >= 0:
                    body[r], link[r] = h[0], h[1]
                    frac[r] = h[2] * sp / length
                    normal[r] = h[4]
        miss = ~np.isfinite(frac)
        body[miss], link[miss] = -1, -1
        return RayHits(frac, body, link, normal, int(rows.size))


def _local(starts: np.ndarray, dirs: np.ndarray, R: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ray origins and directions in each shape's frame: (K, N, 3) each."""
    return (starts[None, :, :] - c[:, None, :]) @ R, dirs @ R


def _aabb_span(starts: np.ndarray, dirs: np.ndarray, lo: np.ndarray, hi: np.ndarray, dims: int) -> tuple[np.ndarray, np.ndarray]:
    """Distances along each ray where it enters and leaves each axis-aligned box
    ``lo``..``hi`` (K, 3) in the first ``dims`` axes (K, N each): entry 0 from inside,
    inf never."""
    near = np.zeros((len(lo), len(starts)))
    far = np.full((len(lo), len(starts)), np.inf)
    for a in range(dims):
        s, d = starts[None, :, a], dirs[None, :, a]
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (lo[:, a:a + 1] - s) / d
            t2 = (hi[:, a:a + 1] - s) / d
        flat = d == 0.0
        inside = (lo[:, a:a + 1] <= s) & (s <= hi[:, a:a + 1])
        near = np.maximum(near, np.where(flat, np.where(inside, -np.inf, np.inf), np.fmin(t1, t2)))
        far = np.minimum(far, np.where(flat, np.where(inside, np.inf, -np.inf), np.fmax(t1, t2)))
    return np.where(near <= far, near, np.inf), far


def _sector_pairs(sorted_bearings: tuple[np.ndarray, np.ndarray], lo: np.ndarray,
                  hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The (shape, ray) pairs that can meet in a level scan: the rays whose bearing (from
    the point all rays' lines pass through; ``sorted_bearings``: the rays' bearings sorted
    and the order that sorts them) lies in shape k's bearing range ``lo[k]``..``hi[k]``
    [rad] (+-inf: all; a range across +-pi is taken round)."""
    k_all = len(lo)
    sb, order = sorted_bearings
    # a range across +-pi is two ranges
    under = np.isfinite(lo) & (lo < -np.pi)
    over = np.isfinite(hi) & (hi > np.pi)
    los = np.concatenate([lo, np.where(under, lo + 2 * np.pi, np.inf), np.where(over, -np.inf, np.inf)])
    his = np.concatenate([hi, np.where(under, np.inf, -np.inf), np.where(over, hi - 2 * np.pi, -np.inf)])
    ks = np.tile(np.arange(k_all), 3)
    i0 = np.searchsorted(sb, los, side="left")
    i1 = np.searchsorted(sb, his, side="right")
    count = np.maximum(i1 - i0, 0)
    k = np.repeat(ks, count)
    first = np.repeat(i0 - np.concatenate([[0], np.cumsum(count)[:-1]]), count)
    n = order[first + np.arange(len(k))]
    return k, n


def _bearings(origin: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bearing range [rad] of each shape's ``points`` (K, M, 2), seen from ``origin``
    outside the shapes, round the bearing of their first point."""
    rel = points - origin[:2]
    ang = np.arctan2(rel[..., 1], rel[..., 0])
    ref = ang[:, :1]
    off = (ang - ref + np.pi) % (2 * np.pi) - np.pi
    return ref[:, 0] + off.min(axis=1) - 1e-9, ref[:, 0] + off.max(axis=1) + 1e-9


def _rect_extent(origin: np.ndarray, R: np.ndarray, c: np.ndarray, half: np.ndarray,
                 corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bearing ranges of upright boxes' rectangles (``corners`` (K, 4, 2)) from ``origin``
    (all bearings for a box the origin is in or on)."""
    lo, hi = _bearings(origin, corners)
    rel = origin[:2] - c[:, :2]
    inside = ((np.abs(np.einsum("ki,ki->k", rel, R[:, :2, 0])) <= half[:, 0] * (1 + 1e-9) + 1e-9)
              & (np.abs(np.einsum("ki,ki->k", rel, R[:, :2, 1])) <= half[:, 1] * (1 + 1e-9) + 1e-9))
    return np.where(inside, -np.inf, lo), np.where(inside, np.inf, hi)


def _circle_extent(origin: np.ndarray, R: np.ndarray, c: np.ndarray, size: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bearing ranges of upright cylinders' circles from ``origin`` (all from within)."""
    rel = c[:, :2] - origin[:2]
    dist = np.hypot(rel[:, 0], rel[:, 1])
    phi = np.arctan2(rel[:, 1], rel[:, 0])
    with np.errstate(divide="ignore", invalid="ignore"):
        half = np.arcsin(np.clip(size[:, 0] / dist, 0.0, 1.0)) + 1e-9
    inside = dist <= size[:, 0] * (1.0 + 1e-9)
    return np.where(inside, -np.inf, phi - half), np.where(inside, np.inf, phi + half)


def _rect_pairs(starts: np.ndarray, dirs: np.ndarray, R: np.ndarray, c: np.ndarray, half: np.ndarray,
                k: np.ndarray, n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Upright boxes cut by a level scan are rectangles in its plane: distance along ray
    ``n`` to rectangle ``k`` (inf: none) and the face normal there, per pair (2D slabs)."""
    ux, uy = R[k, :2, 0], R[k, :2, 1]  # the boxes' x and y axes in the plane
    rx, ry = starts[n, 0] - c[k, 0], starts[n, 1] - c[k, 1]
    dxw, dyw = dirs[n, 0], dirs[n, 1]
    o = (rx * ux[:, 0] + ry * ux[:, 1], rx * uy[:, 0] + ry * uy[:, 1])
    d = (dxw * ux[:, 0] + dyw * ux[:, 1], dxw * uy[:, 0] + dyw * uy[:, 1])
    near, far = [], []
    for a in range(2):
        h = half[k, a]
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (-h - o[a]) / d[a]
            t2 = (h - o[a]) / d[a]
        flat = d[a] == 0.0
        inside = np.abs(o[a]) <= h
        near.append(np.where(flat, np.where(inside, -np.inf, np.inf), np.fmin(t1, t2)))
        far.append(np.where(flat, np.where(inside, np.inf, -np.inf), np.fmax(t1, t2)))
    x_face = near[0] >= near[1]
    t_near = np.where(x_face, near[0], near[1])
    hit = (t_near <= np.minimum(far[0], far[1])) & (t_near >= 0.0)
    dl = np.where(x_face, d[0], d[1])
    normal = np.where(x_face[:, None], R[k, :, 0], R[k, :, 1]) * -np.sign(dl)[:, None]
    return np.where(hit, t_near, np.inf), normal


def _circle_pairs(starts: np.ndarray, dirs: np.ndarray, R: np.ndarray, c: np.ndarray, size: np.ndarray,
                  k: np.ndarray, n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Upright cylinders cut by a level scan are circles in its plane: distance along
    (unit) ray ``n`` to circle ``k`` (inf: none; none from inside) and the normal there."""
    ox, oy = starts[n, 0] - c[k, 0], starts[n, 1] - c[k, 1]
    dx, dy = dirs[n, 0], dirs[n, 1]
    b = ox * dx + oy * dy
    q = ox * ox + oy * oy - size[k, 0] ** 2
    disc = b * b - q
    t = -b - np.sqrt(np.maximum(disc, 0.0))
    t = np.where((disc >= 0.0) & (q > 0.0) & (t >= 0.0), t, np.inf)
    px, py = ox + np.where(np.isfinite(t), t, 0.0) * dx, oy + np.where(np.isfinite(t), t, 0.0) * dy
    r = np.maximum(np.hypot(px, py), 1e-12)
    return t, np.stack([px / r, py / r, np.zeros(len(k))], axis=1)


def _box_entry(starts: np.ndarray, dirs: np.ndarray, R: np.ndarray, c: np.ndarray, half: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance along each ray where it enters each box (K, N) (inf: never, or when the ray
    starts inside: pybullet reports no hit on a convex shape from within) and the local
    axis of the entry face (K, N)."""
    o, d = _local(starts, dirs, R, c)
    h = half[:, None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (-h - o) / d
        t2 = (h - o) / d
    flat = d == 0.0  # parallel to a pair of faces: inside that slab for all t, or never
    inside = np.abs(o) <= h
    t_near = np.where(flat, np.where(inside, -np.inf, np.inf), np.fmin(t1, t2))
    t_far = np.where(flat, np.where(inside, np.inf, -np.inf), np.fmax(t1, t2))
    near, far = t_near.max(axis=2), t_far.min(axis=2)
    axis = t_near.argmax(axis=2)
    hit = (near <= far) & (near >= 0.0)
    return np.where(hit, near, np.inf), axis


def _box_hits(starts: np.ndarray, dirs: np.ndarray, R: np.ndarray, c: np.ndarray, half: np.ndarray):  # type: ignore[no-untyped-def]
    t, axis = _box_entry(starts, dirs, R, c, half)

    def normal(k: np.ndarray, rows: np.ndarray) -> np.ndarray:
        ax = axis[k, rows]
        i = np.arange(len(rows))
        d_local = np.einsum("kji,kj->ki", R[k], dirs[rows])[i, ax]
        return R[k][i, :, ax] * -np.sign(d_local)[:, None]

    return t, normal


def _cyl_hits(starts: np.ndarray, dirs: np.ndarray, R: np.ndarray, c: np.ndarray, size: np.ndarray):  # type: ignore[no-untyped-def]
    """Cylinders along their local z: radius ``size[:, 0]``, half height ``size[:, 1]``."""
    o, d = _local(starts, dirs, R, c)
    r, hz = size[:, 0:1], size[:, 1:2]
    a = d[..., 0] ** 2 + d[..., 1] ** 2
    b = 2.0 * (o[..., 0] * d[..., 0] + o[..., 1] * d[..., 1])
    q = o[..., 0] ** 2 + o[..., 1] ** 2 - r * r
    disc = b * b - 4.0 * a * q
    with np.errstate(divide="ignore", invalid="ignore"):
        t_side = (-b - np.sqrt(np.maximum(disc, 0.0))) / (2.0 * a)
        side_ok = (a > 0) & (disc >= 0) & (t_side >= 0) & (np.abs(o[..., 2] + t_side * d[..., 2]) <= hz)
        t_side = np.where(side_ok, t_side, np.inf)
        caps = []
        for sgn in (1.0, -1.0):
            tc = (sgn * hz - o[..., 2]) / d[..., 2]
            px, py = o[..., 0] + tc * d[..., 0], o[..., 1] + tc * d[..., 1]
            ok = (d[..., 2] * sgn < 0) & (tc >= 0) & (px * px + py * py <= r * r)
            caps.append(np.where(ok, tc, np.inf))
    inside = (q <= 0) & (np.abs(o[..., 2]) <= hz)  # no hit from within (as pybullet)
    t = np.where(inside, np.inf, np.minimum(t_side, np.minimum(caps[0], caps[1])))

    def normal(k: np.ndarray, rows: np.ndarray) -> np.ndarray:
        i = np.arange(len(rows))
        tk = t[k, rows]
        ok, dk = o[k, rows], d[k, rows]
        pt = ok + tk[:, None] * dk
        local = np.zeros((len(rows), 3))
        on_cap = (caps[0][k, rows] == tk) | (caps[1][k, rows] == tk)
        local[on_cap, 2] = np.sign(pt[on_cap, 2])
        rad = ~on_cap
        local[rad, :2] = pt[rad, :2] / np.maximum(np.hypot(pt[rad, 0], pt[rad, 1]), 1e-12)[:, None]
        return np.einsum("kij,kj->ki", R[k], local)[i]

    return t, normal


def _plane_hits(starts: np.ndarray, dirs: np.ndarray, R: np.ndarray, c: np.ndarray, size: np.ndarray):  # type: ignore[no-untyped-def]
    """Planes through their frame's origin with local normal ``size``, hit from the front."""
    nw = np.einsum("kij,kj->ki", R, size)  # world normals (K, 3)
    dn = dirs @ nw.T  # (N, K)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (np.einsum("ki,ki->k", nw, c)[None, :] - starts @ nw.T) / dn
    t = np.where((dn < 0) & (t >= 0), t, np.inf).T

    def normal(k: np.ndarray, rows: np.ndarray) -> np.ndarray:
        return nw[k]

    return t, normal


_HITS = {"box": _box_hits, "cyl": _cyl_hits, "plane": _plane_hits}
#: what a level scan makes of upright boxes and cylinders
_PLANAR_NAME = {"box": "rect", "cyl": "circle"}
#: level-scan kernels: (per-pair hit, bearing range)
_LEVEL = {"rect": (_rect_pairs, _rect_extent), "circle": (_circle_pairs, _circle_extent)}
