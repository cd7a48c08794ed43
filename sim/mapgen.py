"""A world file's static geometry as the real robot's map and planning scene.

A lab that builds a room like a sim world (``sim/worlds/*.yaml``) can run the real robot
on the map and scene the sim uses: :func:`world_map` is the sim's own navigation grid
(:meth:`mmexec.sim.world.World.occupancy`, nominal poses), :func:`mmexec.drivers.maps.write_map` saves it
as a map_server map (YAML + 8-bit PGM) with the world's laser reflectors under a
``reflectors:`` key, and :func:`scene_yaml` prints the
world's static boxes (:meth:`~mmexec.sim.world.World.scene_boxes`) as ``robot.scene``
entries of a run config. Both are what the robot is told: obstacles marked ``unmapped``
and the world's people are left out of the map and the scene (the lidar finds them).
``config/maps/lab.{yaml,pgm}`` were written by::

    .venv/bin/python -m mmexec.sim.mapgen lab config/maps/lab.yaml

which also prints the ``robot.scene`` list of ``config/locobot.yaml`` and
``config/ur5e.yaml`` (both arguments optional: ``lab`` and ``config/maps/WORLD.yaml``).
"""

from __future__ import annotations

import argparse
import contextlib
import math
import sys
from pathlib import Path
from typing import NoReturn

import numpy as np

from mmexec.config.brokenpipe import detach_stdout
from mmexec.config.yamlload import InputError, Mark
from mmexec.drivers.interfaces import OccupancyGrid
from mmexec.drivers.maps import write_map, yaml_number
from mmexec.sim.world import World, load_world

__all__ = ["scene_yaml", "world_map"]



def _world(world: World | str | Path) -> World:
    return world if isinstance(world, World) else load_world(world, randomize=False)


def world_map(world: World | str | Path, resolution: float = 0.05) -> OccupancyGrid:
    """The sim's occupancy grid of ``world`` (a loaded world, a shipped world's name or a
    world file) at its nominal poses: walls, shelves, tables, depots, obstacles and
    reflectors 100, the rest of the room 0 (unmapped obstacles and people too); origin
    at the outer wall corner."""
    return _world(world).occupancy(resolution)


def scene_yaml(world: World | str | Path, indent: int = 4) -> str:
    """The world's static boxes, unmapped obstacles left out, as ``robot.scene`` lines,
    one flow mapping each:
    ``- {name, size [m], xyz [m] (box centre in map), rpy [rad]}`` (every box of a world
    is upright, so rpy is [0, 0, yaw])."""
    pad = " " * indent
    out = []
    for box in _world(world).scene_boxes():
        T = np.asarray(box.pose)
        if abs(T[2, 2] - 1.0) > 1e-9:
            raise ValueError(f"scene_yaml: {box.name} is not upright")
        yaw = math.atan2(T[1, 0], T[0, 0])
        size = ", ".join(yaml_number(s) for s in box.size)
        xyz = ", ".join(yaml_number(v) for v in T[:3, 3])
        out.append(f"{pad}- {{name: {box.name}, size: [{size}], xyz: [{xyz}], rpy: [0, 0, {yaml_number(yaw)}]}}")
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
