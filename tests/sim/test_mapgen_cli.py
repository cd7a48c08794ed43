"""``python -m mmexec.sim.mapgen`` as a user runs it: ``--help`` prints the usage, bad
input is one line on stderr and exit 2 (never a traceback), and a closed stdout pipe
ends quietly with 141 after the map is written."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from mmexec.config.brokenpipe import EXIT_BROKEN_PIPE
from mmexec.sim import mapgen
from mmexec.sim.world import shipped_worlds

MAPGEN = [sys.executable, "-m", "mmexec.sim.mapgen"]


def mapgen_process(*args: str | Path, cwd: Path, stdout: int = subprocess.PIPE) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*MAPGEN, *map(str, args)], cwd=cwd, stdout=stdout, stderr=subprocess.PIPE,
                          stdin=subprocess.DEVNULL, text=True, timeout=120, check=False)


def test_help_prints_the_usage_and_exits_0(tmp_path: Path) -> None:
    res = mapgen_process("--help", cwd=tmp_path)
    assert res.returncode == 0 and res.stderr == ""
    assert res.stdout.startswith(f"usage: {mapgen.PROG} [-h] [WORLD] [OUT.yaml]")
    assert not (tmp_path / "config").exists()  # nothing written (it was a world named '--help')


def test_bad_input_is_one_line_and_exit_2(tmp_path: Path) -> None:
    (tmp_path / "plain.txt").write_text("")
    (tmp_path / "folder.yaml").mkdir()
    cases = {
        ("nosuch",): f"mapgen WORLD: unknown world 'nosuch' (shipped: {', '.join(shipped_worlds())}; "
                     "or give a path to a .yaml file)",
        ("worlds/missing.yaml",): "worlds/missing.yaml:1:1: no such file",
        (str(tmp_path),): f"{tmp_path}:1:1: is a directory, expected a YAML file",
        ("lab", "map.txt"): f"{mapgen.PROG}: OUT 'map.txt': expected a .yaml file path (the .pgm is written beside it)",
        ("lab", "folder.yaml"): f"{mapgen.PROG}: OUT 'folder.yaml': expected a .yaml file path (the .pgm is "
                                "written beside it)",
        ("lab", "plain.txt/map.yaml"): f"{mapgen.PROG}: plain.txt: cannot write: not a folder",
        ("lab", "/proc/mapgen.yaml"): f"{mapgen.PROG}: /proc/mapgen.pgm: cannot write: No such file or directory",
        ("lab", "out.yaml", "extra"): f"{mapgen.PROG}: unrecognized arguments: extra (see '{mapgen.PROG} --help')",
    }
    for args, line in cases.items():
        res = mapgen_process(*args, cwd=tmp_path)
        assert (res.returncode, res.stdout, res.stderr.splitlines()) == (2, "", [line]), args
    assert sorted(p.name for p in tmp_path.iterdir()) == ["folder.yaml", "plain.txt"]  # no stray map


def test_a_closed_stdout_pipe_ends_quietly_after_the_map_is_written(tmp_path: Path) -> None:
    read_end, write_end = os.pipe()
    os.close(read_end)
    try:
        res = mapgen_process("lab", "maps/lab.yaml", cwd=tmp_path, stdout=write_end)
    finally:
        os.close(write_end)
    assert res.returncode == EXIT_BROKEN_PIPE
    assert res.stderr == "wrote maps/lab.yaml and maps/lab.pgm (104 x 84 cells)\n"
    assert (tmp_path / "maps" / "lab.pgm").stat().st_size > 0


def test_main_in_process_returns_the_codes(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert mapgen.main(["--help"]) == 0
    assert capsys.readouterr().out.startswith("usage: ")
    assert mapgen.main(["nosuch", str(tmp_path / "x.yaml")]) == 2
    assert capsys.readouterr().err.startswith("mapgen WORLD: unknown world 'nosuch'")
