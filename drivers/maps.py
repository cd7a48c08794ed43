"""Map files: the map_server format (a YAML beside an 8-bit PGM) read and written.

One home for the format, at the capability contract's level, because the real robot's
backend loads its map (``robot.map``), the simulator writes one for a sim world
(``python -m mmexec.sim.mapgen``), and skills read the result as an
:class:`~mmexec.drivers.interfaces.OccupancyGrid` through the capability layer.

:func:`load_map` reads a map (``FILE:LINE:COL`` errors; the image is read only if it is a
regular file of at most :data:`MAX_IMAGE_BYTES`), :func:`write_map` writes one (trinary,
negate 0, map_server's default thresholds) with the laser-reflector posts under an mmexec
``reflectors:`` key that map_server ignores (the localiser reads it:
:mod:`mmexec.skills.localization.landmarks`). Grid conventions as
:class:`~mmexec.drivers.interfaces.OccupancyGrid`: row 0 at the origin, rows along +y,
0 free, 100 occupied, -1 unknown.
"""

from __future__ import annotations

import json
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, Protocol

import numpy as np

from mmexec.config.yamlload import InputError, Mark, Problems, bind, load_yaml, mark_of, read_file
from mmexec.drivers.interfaces import OccupancyGrid, Pose2D, ReflectorPost

__all__ = [
    "FREE",
    "MAX_IMAGE_BYTES",
    "OCCUPIED",
    "UNKNOWN",
    "MapFile",
    "MapReflector",
    "load_map",
    "pgm_bytes",
    "read_pgm",
    "write_map",
    "yaml_number",
]

#: largest map image read [bytes]: a 4000 x 4000 cell map (200 x 200 m at 5 cm)
MAX_IMAGE_BYTES = 16 << 20
#: map_saver's pixel values (negate 0): occupied black, free white, unknown grey
OCCUPIED, FREE, UNKNOWN = 0, 254, 205


class _Named(Protocol):
    """A reflector post as :func:`write_map` needs it (a world's or a map's)."""

    name: str
    position: tuple[float, float]
    radius: float


@dataclass(frozen=True)
class MapReflector:
    """A laser-reflector post of the map (an mmexec key of the map YAML, which map_server
    ignores): ``name``, centre ``position`` ``[x, y]`` in ``map`` [m], post ``radius`` [m].
    Read with :func:`mmexec.skills.localization.landmarks.load_reflectors`."""

    name: str
    position: tuple[float, float]
    radius: float

    def validate(self) -> list[str]:
        return [] if self.radius > 0 else [f"reflector {self.name!r}: radius must be > 0 m, got {self.radius}"]


@dataclass(frozen=True)
class MapFile:
    """A map_server map description (the YAML next to the PGM).

    ``origin`` is ``[x, y, yaw]`` of the lower-left pixel's corner in ``map`` [m, m, rad];
    ``resolution`` [m/pixel]; thresholds are occupancy probabilities in [0, 1];
    ``reflectors``: the laser-reflector landmarks, if the map has any.
    """

    image: str
    resolution: float
    origin: tuple[float, float, float]
    negate: int = 0
    occupied_thresh: float = 0.65
    free_thresh: float = 0.196
    mode: Literal["trinary", "scale"] = "trinary"
    reflectors: tuple[MapReflector, ...] = ()

    def validate(self) -> list[str]:
        errs = []
        if not self.resolution > 0:
            errs.append(f"resolution: must be > 0 m/pixel, got {self.resolution}")
        if self.negate not in (0, 1):
            errs.append(f"negate: expected 0 or 1, got {self.negate}")
        if not 0.0 <= self.free_thresh < self.occupied_thresh <= 1.0:
            errs.append(
                f"thresholds: need 0 <= free_thresh < occupied_thresh <= 1, got "
                f"{self.free_thresh} and {self.occupied_thresh}"
            )
        return errs


def read_pgm(path: str | Path) -> np.ndarray:
    """Read a binary (P5) or ASCII (P2) 8-bit PGM file into an HxW uint8 array (row 0 at
    the top of the picture). Raises :class:`InputError` naming the file on bad content."""
    name = str(path)
    data = read_file(path, limit=MAX_IMAGE_BYTES, expected="a PGM map image")
    tokens: list[bytes] = []
    pos = 0
    while len(tokens) < 4:
        while pos < len(data) and data[pos : pos + 1].isspace():
            pos += 1
        if pos < len(data) and data[pos : pos + 1] == b"#":
            while pos < len(data) and data[pos : pos + 1] not in (b"\n", b"\r"):
                pos += 1
            continue
        start = pos
        while pos < len(data) and not data[pos : pos + 1].isspace() and data[pos : pos + 1] != b"#":
            pos += 1
        if start == pos:
            raise InputError.at(Mark(name, 1, 1), "truncated PGM header (expected magic, width, height, maxval)")
        tokens.append(data[start:pos])
    magic = tokens[0]
    if magic not in (b"P5", b"P2"):
        raise InputError.at(Mark(name, 1, 1), f"not a PGM image (magic {magic[:8]!r}, expected P5 or P2)")
    try:
        w, h, maxval = (int(t) for t in tokens[1:4])
    except ValueError:
        raise InputError.at(Mark(name, 1, 1), "bad PGM header: width, height and maxval must be integers") from None
    if w <= 0 or h <= 0 or not 0 < maxval < 256:
        raise InputError.at(Mark(name, 1, 1), f"unsupported PGM: {w}x{h}, maxval {maxval} (need 8-bit)")
    if magic == b"P5":
        body = data[pos + 1 : pos + 1 + w * h]
        if len(body) != w * h:
            raise InputError.at(Mark(name, 1, 1), f"PGM data truncated: {len(body)} of {w * h} bytes")
        img = np.frombuffer(body, dtype=np.uint8).reshape(h, w)
    else:
        try:
            vals = [int(t) for t in data[pos:].split()]
        except ValueError:
            raise InputError.at(Mark(name, 1, 1), "bad ASCII PGM pixel value") from None
        if len(vals) < w * h:
            raise InputError.at(Mark(name, 1, 1), f"PGM data truncated: {len(vals)} of {w * h} values")
        img = np.asarray(vals[: w * h], dtype=np.int64).clip(0, 255).astype(np.uint8).reshape(h, w)
    if maxval != 255:
        img = (img.astype(np.float64) * (255.0 / maxval)).round().clip(0, 255).astype(np.uint8)
    return img


def load_map(yaml_path: str | Path) -> OccupancyGrid:
    """Load a map_server-style map (YAML + PGM) as an :class:`OccupancyGrid` in ``map``.

    Errors (missing keys, wrong types, unreadable image) raise :class:`InputError` with
    ``FILE:LINE:COL: message``. The image is flipped so that grid row 0 is the bottom
    row of the picture (map_server convention). The map's ``reflectors:`` become the
    grid's :attr:`~mmexec.drivers.interfaces.OccupancyGrid.reflectors`.
    """
    raw = load_yaml(yaml_path)
    name = str(yaml_path)
    problems = Problems()
    mf = bind(MapFile, raw, mark_of(raw, Mark(name, 1, 1)), "", problems)
    problems.raise_if_any()
    assert isinstance(mf, MapFile)
    img_path = Path(mf.image)
    if not img_path.is_absolute():
        img_path = Path(yaml_path).parent / img_path
    if not img_path.exists():
        vm = raw.value_mark("image") if hasattr(raw, "value_mark") else Mark(name, 1, 1)
        raise InputError.at(vm, f"image: no such file {str(img_path)!r}")
    img = read_pgm(img_path)
    pix = img.astype(np.float64)
    p = pix / 255.0 if mf.negate else (255.0 - pix) / 255.0
    data = np.full(img.shape, -1, dtype=np.int8)
    if mf.mode == "trinary":
        data[p > mf.occupied_thresh] = 100
        data[p < mf.free_thresh] = 0
    else:
        data[p > mf.occupied_thresh] = 100
        data[p < mf.free_thresh] = 0
        mid = (p >= mf.free_thresh) & (p <= mf.occupied_thresh)
        scaled = 99.0 * (p - mf.free_thresh) / (mf.occupied_thresh - mf.free_thresh)
        data[mid] = np.round(scaled[mid]).astype(np.int8)
    data = np.ascontiguousarray(data[::-1])
    ox, oy, oyaw = mf.origin
    posts = tuple(ReflectorPost(r.name, (float(r.position[0]), float(r.position[1])), r.radius) for r in mf.reflectors)
    return OccupancyGrid(data=data, resolution=mf.resolution, origin=Pose2D(ox, oy, oyaw), reflectors=posts)


def pgm_bytes(grid: OccupancyGrid, comment: str = "") -> bytes:
    """``grid`` as a binary PGM (P5, maxval 255) in map_server's layout: picture row 0 is
    the grid's last row (the map's top). Values >= 50 are occupied, 0..49 free, < 0
    unknown."""
    d = np.asarray(grid.data)
    img = np.full(d.shape, FREE, dtype=np.uint8)
    img[d >= 50] = OCCUPIED
    img[d < 0] = UNKNOWN
    img = np.ascontiguousarray(img[::-1])
    head = "P5\n" + "".join(f"# {ln}\n" for ln in comment.splitlines())
    head += f"{img.shape[1]} {img.shape[0]}\n255\n"
    return head.encode("ascii") + img.tobytes()


def write_map(grid: OccupancyGrid, yaml_path: str | Path, *, comment: str = "",
              reflectors: Sequence[_Named] = ()) -> tuple[Path, Path]:
    """Write ``grid`` as ``yaml_path`` plus a PGM of the same stem next to it (trinary,
    negate 0, map_server's default thresholds), with ``reflectors`` (positions in ``map``)
    listed under the YAML's ``reflectors:`` key when there are any. Returns both paths."""
    o = grid.origin
    if abs(o.theta) > 1e-12:
        raise ValueError("write_map: map_server maps with a rotated origin are not supported")
    yaml_path = Path(yaml_path)
    pgm_path = yaml_path.with_suffix(".pgm")
    yaml_path.parent.mkdir(parents=True, exist_ok=True)
    pgm_path.write_bytes(pgm_bytes(grid, comment))
    lines = [f"# {ln}" for ln in comment.splitlines()] + [
        f"image: {pgm_path.name}",
        f"resolution: {grid.resolution:g}           # m per pixel",
        f"origin: [{o.x:g}, {o.y:g}, 0.0]     # lower-left pixel corner in map [m, m, rad]",
        "negate: 0",
        "occupied_thresh: 0.65",
        "free_thresh: 0.196",
        "mode: trinary",
    ]
    if reflectors:
        lines.append("reflectors:             # laser-reflector posts (mmexec): centre [x, y] in map [m], radius [m]")
        lines += [f"  - {{name: {_name(r.name)}, position: [{yaml_number(r.position[0])}, {yaml_number(r.position[1])}], "
                  f"radius: {yaml_number(r.radius)}}}" for r in reflectors]
    yaml_path.write_text("\n".join(lines) + "\n")
    return yaml_path, pgm_path


def _name(name: str) -> str:
    """``name`` as a YAML flow scalar: plain when that reads back as the same string,
    else double-quoted (JSON's quoting is valid YAML)."""
    plain = re.fullmatch(r"[A-Za-z_][A-Za-z0-9_.-]*", name) and name.lower() not in _YAML_WORDS
    return name if plain else json.dumps(name)


#: plain scalars YAML reads as booleans or null
_YAML_WORDS = frozenset({"true", "false", "yes", "no", "on", "off", "y", "n", "null"})


def yaml_number(v: float) -> str:
    """``v`` rounded to the micrometre / microradian, as a short YAML number."""
    r = round(float(v), 6)
    return "0" if r == 0 else f"{r:.10g}"
