"""locate_object's trust in a closer look (skills/fetch_object/skills.py): a closer view
that moves the object's centre by more than RELOCATE_TOLERANCE and saw it more obliquely
to its support's normal than the view it was found from is not trusted."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from mmexec.skills.fetch_object.skills import RELOCATE_TOLERANCE, _more_oblique, _obliquity


def _target(centre, camera_xy, normal=(-1.0, 0.0)):
    T_map_base = np.eye(4)
    T_map_base[:2, 3] = camera_xy
    frame = SimpleNamespace(T_map_base=T_map_base, T_base_camera=np.eye(4))
    return SimpleNamespace(centre=np.asarray(centre, dtype=float), frame=frame, normal=normal)


def test_obliquity_of_a_view():
    t = _target((4.7, 2.3, 0.3), (3.6, 2.3))
    assert abs(_obliquity(t, (-1.0, 0.0))) < 1e-9                     # face-on
    t = _target((4.7, 2.3, 0.3), (4.2, 2.8))
    assert abs(_obliquity(t, (-1.0, 0.0)) - np.pi / 4) < 1e-9        # from 45 degrees


def test_a_more_oblique_view_that_disagrees_is_not_trusted():
    far = _target((4.71, 2.37, 0.29), (3.6, 2.0))          # the likely place, nearly face-on
    beside = _target((4.67, 2.435, 0.29), (4.25, 2.78))    # beside the blocker, 7 cm off
    assert _more_oblique(far, beside)
    # within the tolerance: trusted (the closer view's few mm are better)
    close = _target((4.71 + 0.5 * RELOCATE_TOLERANCE, 2.37, 0.29), (4.25, 2.78))
    assert not _more_oblique(far, close)
    # more face-on than the far view: trusted even when it moves the estimate
    front = _target((4.66, 2.37, 0.29), (4.1, 2.37))
    assert not _more_oblique(far, front)
    # no support normal known: trusted
    assert not _more_oblique(_target((4.71, 2.37, 0.29), (3.6, 2.0), normal=None), beside)
