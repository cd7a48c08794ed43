"""The likelihood field's look-up (one gather on a padded field) reads exactly what a
per-point look-up with an on-map mask reads, off the map and for nan points too."""

from __future__ import annotations

import numpy as np

from mmexec.drivers.interfaces import OccupancyGrid, Pose2D
from mmexec.skills.localization.likelihood import BeamModel, LikelihoodField


def _masked(f: LikelihoodField, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    ox, oy, c, s = f._origin
    res = f.grid.resolution
    with np.errstate(invalid="ignore"):
        col = np.floor((c * (x - ox) + s * (y - oy)) / res + 1e-9).astype(np.int64)
        row = np.floor((-s * (x - ox) + c * (y - oy)) / res + 1e-9).astype(np.int64)
    h, w = f.distance.shape
    inside = (row >= 0) & (row < h) & (col >= 0) & (col < w)
    out = np.full(x.shape, f.model.max_occ_dist)
    out[inside] = f.distance[row[inside], col[inside]]
    return out


def test_the_gather_reads_what_a_masked_look_up_reads():
    rng = np.random.default_rng(7)
    data = np.zeros((37, 53), dtype=np.int8)
    data[rng.random(data.shape) < 0.05] = 100
    g = OccupancyGrid(data=data, resolution=0.05, origin=Pose2D(-0.4, 0.3, 0.2))
    f = LikelihoodField(g, BeamModel(max_occ_dist=1.0))
    x = rng.uniform(-2.0, 4.0, (300, 60))
    y = rng.uniform(-2.0, 4.0, (300, 60))
    x[0, :4] = [1e12, -1e12, np.nan, 0.0]
    y[0, :4] = [0.0, 5.0, 1.0, np.inf]
    with np.errstate(invalid="ignore"):
        got = f.distance_at(x, y)
    want = _masked(f, x, y)
    assert got.shape == want.shape
    np.testing.assert_array_equal(got, want)
    assert (got < 1.0).any() and (got == 1.0).any()
