"""A map's reflector posts, read from the ``reflectors:`` key of its map_server YAML."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mmexec.config.yamlload import InputError
from mmexec.drivers.maps import load_map
from mmexec.skills.localization import ReflectorConfig, load_reflectors

HEAD = "image: m.pgm\nresolution: 0.05\norigin: [-0.1, -0.1, 0.0]\n"


def _map(tmp: Path, tail: str = "") -> Path:
    (tmp / "m.pgm").write_bytes(b"P5\n4 3\n255\n" + bytes([254] * 12))
    path = tmp / "m.yaml"
    path.write_text(HEAD + tail)
    return path


def test_the_reflectors_key_is_read_and_load_map_returns_the_same_grid(tmp_path: Path) -> None:
    plain = load_map(_map(tmp_path)).data.copy()
    path = _map(tmp_path, "reflectors:\n  - {name: a, position: [0.1, 0.2], radius: 0.04}\n"
                          "  - {name: b, position: [3.0, 0.2], radius: 0.04}\n")
    assert np.array_equal(load_map(path).data, plain)
    refl = load_reflectors(path)
    assert refl.names == ("a", "b") and len(refl) == 2
    assert np.array_equal(refl.positions, [[0.1, 0.2], [3.0, 0.2]])
    assert refl.radius == 0.04
    assert refl.config(ReflectorConfig(alpha=10.0)) == ReflectorConfig(alpha=10.0, post_radius=0.04)


def test_a_map_without_reflectors_has_none(tmp_path: Path) -> None:
    refl = load_reflectors(_map(tmp_path))
    assert len(refl) == 0 and refl.positions.shape == (0, 2) and refl.radius == 0.0
    assert refl.config() == ReflectorConfig()


@pytest.mark.parametrize(("tail", "message"), [
    ("reflectors:\n  - {name: a, position: [0, 0], radius: 0.04}\n  - {name: a, position: [1, 0], radius: 0.04}\n",
     r"m.yaml:5:3: reflectors: names used twice: a"),
    ("reflectors:\n  - {name: a, position: [0, 0], radius: 0.04}\n  - {name: b, position: [1, 0], radius: 0.05}\n",
     r"m.yaml:5:3: reflectors: posts of different radii \[0.04, 0.05\] m"),
    ("reflectors:\n  - {name: a, position: [0, 0], radius: 0}\n", r"m.yaml:5:5: reflectors\[0\]: reflector 'a': radius must be > 0"),
    ("reflectors:\n  - {name: a, position: [0, 0]}\n", r"m.yaml:5:5: reflectors\[0\].radius: missing required key"),
    ("reflectors:\n  - {name: a, position: [0, 0], radius: 0.04, height: 1}\n", r"m.yaml:5:\d+: reflectors\[0\].height: unknown key"),
])
def test_bad_reflector_lists_are_located_errors(tmp_path: Path, tail: str, message: str) -> None:
    with pytest.raises(InputError, match=message):
        load_reflectors(_map(tmp_path, tail))
