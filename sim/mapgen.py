"""A world file's static geometry as the real robot's map and planning scene.

A lab that builds a room like a sim world (``sim/worlds/*.yaml``) can run the real robot
on the map and scene the sim uses: :func:`world_map` is the sim's own navigation grid
(:meth:`mmexec.sim.world.World.occupancy`, nominal poses), :func:`write_map` saves an
occupancy grid as a map_server map (YAML + 8-bit PGM, read back by
:func:`mmexec.skills.navigation.grid.load_map`) with the world's laser reflectors under a
``reflectors:`` key (name, centre ``position`` [x, y] in ``map`` [m], post ``radius`` [m];
map_server ignores the key, :func:`mmexec.skills.localization.landmarks.load_reflectors`
reads it), and :func:`scene_yaml` prints the
world's static boxes (:meth:`~mmexec.sim.world.World.scene_boxes`) as ``robot.scene``
entries of a run config. ``config/maps/lab.{yaml,pgm}`` were written by::

    .venv/bin/python -m mmexec.sim.mapgen lab config/maps/lab.yaml

which also prints the ``robot.scene`` list of ``config/locobot.yaml`` and
``config/ur5e.yaml`` (both arguments optional: ``lab`` and ``config/maps/WORLD.yaml``).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import re
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import NoReturn

import numpy as np

from mmexec.config.brokenpipe import detach_stdout
from mmexec.config.yamlload import InputError, Mark
from mmexec.drivers.interfaces import OccupancyGrid
from mmexec.sim.world import Reflector, World, load_world

__all__ = ["FREE", "OCCUPIED", "UNKNOWN", "pgm_bytes", "scene_yaml", "world_map", "write_map"]

#: map_saver's pixel values (negate 0): occupied black, free white, unknown grey
OCCUPIED, FREE, UNKNOWN = 0, 254, 205


def _world(world: World | str | Path) -> World:
    return world if isinstance(world, World) else load_world(world, randomize=False)


def world_map(world: World | str | Path, resolution: float = 0.05) -> OccupancyGrid:
    """The sim's occupancy grid of ``world`` (a loaded world, a shipped world's name or a
    world file) at its nominal poses: walls, shelves, tables, depots, obstacles and
    reflectors 100, the rest of the room 0; origin at the outer wall corner."""
    return _world(world).occupancy(resolution)


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
              reflectors: Sequence[Reflector] = ()) -> tuple[Path, Path]:
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
        lines += [f"  - {{name: {_name(r.name)}, position: [{_num(r.position[0])}, {_num(r.position[1])}], "
                  f"radius: {_num(r.radius)}}}" for r in reflectors]
    yaml_path.write_text("\n".join(lines) + "\n")
    return yaml_path, pgm_path


def _name(name: str) -> str:
    """``name`` as a YAML flow scalar: plain when that reads back as the same string,
    else double-quoted (JSON's quoting is valid YAML)."""
    plain = re.fullmatch(r"[A-Za-z_][A-Za-z0-9_.-]*", name) and name.lower() not in _YAML_WORDS
    return name if plain else json.dumps(name)


#: plain scalars YAML reads as booleans or null
_YAML_WORDS = frozenset({"true", "false", "yes", "no", "on", "off", "y", "n", "null"})


def _num(v: float) -> str:
    r = round(float(v), 6)
    return "0" if r == 0 else f"{r:.10g}"


def scene_yaml(world: World | str | Path, indent: int = 4) -> str:
    """The world's static boxes as ``robot.scene`` lines, one flow mapping each:
    ``- {name, size [m], xyz [m] (box centre in map), rpy [rad]}`` (every box of a world
    is upright, so rpy is [0, 0, yaw])."""
    pad = " " * indent
    out = []
    for box in _world(world).scene_boxes():
        T = np.asarray(box.pose)
        if abs(T[2, 2] - 1.0) > 1e-9:
            raise ValueError(f"scene_yaml: {box.name} is not upright")
        yaw = math.atan2(T[1, 0], T[0, 0])
        size = ", ".join(_num(s) for s in box.size)
        xyz = ", ".join(_num(v) for v in T[:3, 3])
        out.append(f"{pad}- {{name: {box.name}, size: [{size}], xyz: [{xyz}], rpy: [0, 0, {_num(yaw)}]}}")
    return "\n".join(out) + "\n"


#: How the command is run (its name in usage and error lines).
PROG = "python -m mmexec.sim.mapgen"
#: Exit codes: written, bad input (one line on stderr); stdout's reader went away is
#: :data:`~mmexec.config.brokenpipe.EXIT_BROKEN_PIPE` (141), as for ``mmexec``.
EXIT_OK, EXIT_INPUT = 0, 2


class _ArgMark(Mark):
    """A command-line argument as an error location, printed as its name."""

    __slots__ = ()

    def __str__(self) -> str:
        return self.file


class _UsageError(Exception):
    """A bad command line (one line, exit 2)."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        raise _UsageError(f"{self.prog}: {message} (see '{self.prog} --help')")


def _parser() -> argparse.ArgumentParser:
    p = _Parser(prog=PROG, description="Write a world's occupancy grid as a map_server map (YAML + PGM) and "
                                       "print its static boxes as robot.scene lines of a run config.")
    p.add_argument("world", nargs="?", default="lab", metavar="WORLD",
                   help="a shipped world's name or a world .yaml file (default lab)")
    p.add_argument("out", nargs="?", type=Path, metavar="OUT.yaml",
                   help="the map's YAML; the PGM goes beside it (default config/maps/WORLD.yaml)")
    return p


def main(argv: list[str] | None = None) -> int:
    """``python -m mmexec.sim.mapgen [WORLD] [OUT.yaml]``: write the map, print the scene.
    Returns the exit code: 0 written, 2 bad input (one line per problem on stderr: an
    unknown world, a world file's problems as FILE:LINE:COL, an OUT that is not a
    writable .yaml path), 141 when stdout's reader went away (quietly)."""
    try:
        args = _parser().parse_args(sys.argv[1:] if argv is None else argv)
    except _UsageError as e:
        print(e, file=sys.stderr)
        return EXIT_INPUT
    except SystemExit as e:  # --help printed the usage
        return int(e.code or 0)
    out: Path = args.out if args.out is not None else Path("config/maps") / f"{Path(args.world).stem}.yaml"
    if out.suffix not in (".yaml", ".yml") or out.is_dir():
        print(f"{PROG}: OUT {str(out)!r}: expected a .yaml file path (the .pgm is written beside it)", file=sys.stderr)
        return EXIT_INPUT
    try:
        world = load_world(args.world, randomize=False, mark=_ArgMark("mapgen WORLD", 0, 0))
    except InputError as e:
        for problem in e.problems:
            print(problem, file=sys.stderr)
        return EXIT_INPUT
    grid = world.occupancy(0.05)
    source = Path(world.source)
    with contextlib.suppress(ValueError):  # a world outside the package keeps its own path
        source = source.resolve().relative_to(Path(__file__).resolve().parents[1])
    try:
        yaml_path, pgm_path = write_map(grid, out, reflectors=world.spec.reflectors, comment=(
            f"world {world.name!r} ({source.as_posix()}) at its nominal poses, written by mmexec.sim.mapgen"))
    except OSError as e:  # FileExistsError: mkdir met a file where a folder of OUT belongs
        why = "not a folder" if isinstance(e, FileExistsError) else e.strerror or str(e)
        print(f"{PROG}: {e.filename or out}: cannot write: {why}", file=sys.stderr)
        return EXIT_INPUT
    print(f"wrote {yaml_path} and {pgm_path} ({grid.width} x {grid.height} cells)", file=sys.stderr)
    try:
        print("  scene:  # static boxes in map for arm planning: name, size [m], xyz centre [m], rpy [rad]")
        print(scene_yaml(world), end="")
        sys.stdout.flush()
    except BrokenPipeError:  # stdout's reader went away (`| head`): exit quietly
        return detach_stdout()
    return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
