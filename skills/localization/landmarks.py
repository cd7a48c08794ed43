"""The laser-reflector landmarks of a map, read from its map_server YAML.

A map with reflectors lists them beside map_server's keys (map_server ignores the key;
:func:`mmexec.drivers.maps.load_map` validates it and returns the grid as
before)::

    image: lab.pgm
    resolution: 0.05
    origin: [-0.1, -0.1, 0.0]
    ...
    reflectors:
      - {name: refl_sw, position: [0.1, 0.1], radius: 0.025}
      - {name: refl_se, position: [4.9, 0.1], radius: 0.025}
      - {name: refl_nw, position: [0.1, 3.9], radius: 0.025}

``position`` is the post's centre in ``map`` [m], ``radius`` its radius [m].
``python -m mmexec.sim.mapgen`` writes the key for a sim world; for a real room, measure
the posts in the map frame (docs/localization.md).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from mmexec.config.yamlload import InputError, Mark, Problems, bind, load_yaml, mark_of
from mmexec.drivers.maps import MapFile
from mmexec.skills.localization.reflectors import ReflectorConfig

__all__ = ["ReflectorMap", "load_reflectors"]


@dataclass(frozen=True)
class ReflectorMap:
    """The map's reflector posts: ``names``, centres ``positions`` ``(K, 2)`` in ``map``
    [m], and the posts' common ``radius`` [m] (0 when there are none)."""

    names: tuple[str, ...]
    positions: np.ndarray
    radius: float

    def __len__(self) -> int:
        return len(self.names)

    def config(self, base: ReflectorConfig | None = None) -> ReflectorConfig:
        """``base`` (default :class:`ReflectorConfig`) with this map's post radius."""
        cfg = base or ReflectorConfig()
        return replace(cfg, post_radius=self.radius) if self.radius > 0 else cfg


def load_reflectors(map_yaml: str | Path) -> ReflectorMap:
    """The reflectors of the map described by ``map_yaml`` (none when it has no
    ``reflectors:`` key). Raises :class:`InputError` (``FILE:LINE:COL``) for a bad map
    file, a repeated name, or posts of different radii (the extraction fits one radius)."""
    raw = load_yaml(map_yaml)
    problems = Problems()
    mf = bind(MapFile, raw, mark_of(raw, Mark(str(map_yaml), 1, 1)), "", problems)
    problems.raise_if_any()
    assert isinstance(mf, MapFile)
    refl = mf.reflectors
    where = raw.value_mark("reflectors") if "reflectors" in raw else Mark(str(map_yaml), 1, 1)
    names = [r.name for r in refl]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise InputError.at(where, f"reflectors: names used twice: {', '.join(twice)}")
    radii = sorted({r.radius for r in refl})
    if radii and radii[-1] - radii[0] > 1e-6:
        raise InputError.at(where, f"reflectors: posts of different radii {radii} m; the extraction fits one "
                                   "radius: use posts of one size")
    pos = np.array([r.position for r in refl], dtype=np.float64).reshape(-1, 2)
    return ReflectorMap(tuple(names), pos, radii[0] if radii else 0.0)
