"""The hostile-input corpus: every case runs the real ``mmexec`` command in a subprocess,
as a user would, and must end in ONE located line on stderr and exit status 2: never a
traceback, an ``internal error``, exit 0, a hang, or memory filling up.

Static cases are the files ``cases/*.yaml`` whose first line is ``# expect: TEXT`` and
second line ``# run: ARGS``; ``TEXT`` starting ``LINE:COL:`` is expected after the case's
own path. ``ARGS`` may name ``{case}`` (the file), ``{mission}`` and ``{config}`` (the
valid ``cases/valid_mission.yaml`` and ``cases/mock_config.yaml``) and ``{log}``.
Generated cases (FIFOs, devices, sparse files, symlinks, command-line flags) are built
in a temporary folder by the functions below. Items of issue 9: 8 non-finite and absurd
numbers, 9 files that are not regular or too large, 10 includes and worlds outside the
allowed folders, 11 symlink loops, ``sys.exit()`` in a skill module, negative baud
rates, bad ``--seed``; 12 terminal escape sequences in user text.

Each subprocess runs with a 2 GiB address-space limit and a generous time limit, so a
regression (reading ``/dev/zero``, waiting on a FIFO) fails the test instead of taking
the machine or the test run with it; no test asserts how long anything takes.
"""

from __future__ import annotations

import os
import re
import resource
import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
CASES = HERE / "cases"
MODULES = CASES / "modules"
MISSION = CASES / "valid_mission.yaml"
CONFIG = CASES / "mock_config.yaml"
MMEXEC = Path(sys.executable).with_name("mmexec")
STATIC = sorted(p for p in CASES.glob("*.yaml") if p.read_text().startswith("# expect: "))
#: terminal control characters that must never reach stderr/stdout raw (newline aside)
CONTROL = re.compile("[\x00-\x09\x0b-\x1f\x7f-\x9f\u202a-\u202e\u2066-\u2069]")
#: a hang guard only (the commands take well under a second), never an assertion
GUARD_S = 120
ADDRESS_SPACE = 2 << 30


@dataclass
class Result:
    rc: int
    out: str
    err: str


def _limit_memory() -> None:  # pragma: no cover - runs in the child
    resource.setrlimit(resource.RLIMIT_AS, (ADDRESS_SPACE, ADDRESS_SPACE))


def mmexec(*argv: str | Path, cwd: Path = CASES) -> Result:
    """Run the ``mmexec`` command; the user skill modules of ``cases/modules`` importable."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(MODULES), os.environ.get("PYTHONPATH")])))
    env.pop("MMEXEC_DEBUG", None)
    try:
        proc = subprocess.run([str(MMEXEC), *map(str, argv)], cwd=cwd, env=env, capture_output=True,
                              stdin=subprocess.DEVNULL, timeout=GUARD_S, preexec_fn=_limit_memory, check=False)
    except subprocess.TimeoutExpired:
        pytest.fail(f"mmexec {' '.join(map(str, argv))} hung")
    return Result(proc.returncode, proc.stdout.decode("utf-8", "backslashreplace"),
                  proc.stderr.decode("utf-8", "backslashreplace"))


def assert_one_located_line(res: Result, expect: str) -> None:
    """Exit 2 and exactly one stderr line containing ``expect``, no raw control characters."""
    assert res.rc == 2, f"exit {res.rc}\nstdout: {res.out}\nstderr: {res.err}"
    lines = res.err.splitlines()
    assert len(lines) == 1, res.err
    assert expect in lines[0], lines[0]
    assert "Traceback" not in res.err and "internal error" not in res.err
    assert not CONTROL.search(res.err), repr(res.err)


# --------------------------------------------------------------------------- static cases


def _header(path: Path) -> tuple[str, list[str]]:
    first, second = path.read_text().splitlines()[:2]
    expect = first.removeprefix("# expect: ")
    assert second.startswith("# run: "), f"{path.name}: second line must be '# run: ...'"
    return expect, second.removeprefix("# run: ").split()


def test_the_corpus_covers_every_item() -> None:
    items = {p.name[1:3] for p in STATIC}
    assert {"08", "10", "11", "12"} <= items and len(STATIC) >= 20


@pytest.mark.parametrize("case", STATIC, ids=lambda p: p.stem)
def test_static_case(case: Path, tmp_path: Path) -> None:
    expect, args = _header(case)
    names = {"case": case, "mission": MISSION, "config": CONFIG, "log": tmp_path / "run.jsonl"}
    res = mmexec(*(a.format(**names) for a in args))
    assert_one_located_line(res, f"{case}:{expect}" if re.match(r"\d+:\d+: ", expect) else expect)


# --------------------------------------------------------------------------- generated cases

#: name -> builder(tmp folder) -> (argv, expected text)
Builder = Callable[[Path], tuple[list[str | Path], str]]
GENERATED: dict[str, Builder] = {}


def case(name: str) -> Callable[[Builder], Builder]:
    def register(fn: Builder) -> Builder:
        GENERATED[name] = fn
        return fn

    return register


def _mission_including(tmp: Path, target: str) -> Path:
    m = tmp / "m.yaml"
    m.write_text(f"tree:\n  include: {target}\n")
    return m


def _fifo(path: Path) -> Path:
    os.mkfifo(path)
    return path


def _sparse(path: Path, size: int = 3 << 30) -> Path:
    with path.open("wb") as f:  # what `truncate -s 3G` makes: no blocks on disk
        f.truncate(size)
    return path


def _run_argv(tmp: Path, *extra: str) -> list[str | Path]:
    """``mmexec run`` of the valid mission on the mock config, one request unless ``extra`` gives one."""
    request = [] if "--request" in extra or "--requests" in extra else ["--request", "x=1"]
    return ["run", MISSION, "--config", CONFIG, *request, *extra, "--log", tmp / "l.jsonl"]


#: command-line values (items 8 and 11): name -> (run flags, expected line)
FLAG_CASES: dict[str, tuple[tuple[str, ...], str]] = {
    "08_request_nan": (("--request", "x=nan"), "--request #1: request 1: request field 'x': expected a finite number, got nan"),
    "08_request_overflow": (("--request", "x=1e999"),
                            "--request #1: request 1: request field 'x': expected a finite number, got inf"),
    "08_param_inf": (("--param", "pause=inf"), "--param #1: parameter 'pause': expected a finite number, got inf"),
    "08_request_timeout_nan": (("--request-timeout", "nan"),
                               "--request-timeout: expected clock seconds > 0 and at most 1e+06, got nan"),
    "08_rate_zero": (("--rate", "0"), "--rate: expected a tick rate in [1, 1000] Hz, got 0"),
    "08_rate_inf": (("--rate", "inf"), "--rate: expected a tick rate in [1, 1000] Hz, got inf"),
    "11_seed_negative": (("--seed", "-1"), "--seed: expected an integer in 0..4294967295, got -1"),
    "11_seed_too_large": (("--seed", str(2**64)), f"--seed: expected an integer in 0..4294967295, got {2**64}"),
}
for _name, (_flags, _expect) in FLAG_CASES.items():
    GENERATED[_name] = lambda tmp, flags=_flags, expect=_expect: (_run_argv(tmp, *flags), expect)


def _campaign_argv(tmp: Path, *extra: str) -> list[str | Path]:
    """``mmexec campaign`` of the valid mission on the mock config, one trial."""
    return ["campaign", MISSION, "--config", CONFIG, "--trials", "1", "--request", "x=1",
            "--out", tmp / "camp", *extra]


#: the same values given to ``mmexec campaign`` (checked before any trial starts)
CAMPAIGN_FLAG_CASES: dict[str, tuple[tuple[str, ...], str]] = {
    "08_campaign_request_timeout_nan": (("--request-timeout", "nan"),
                                        "--request-timeout: expected seconds > 0 and at most 1e+06, got nan"),
    "08_campaign_trial_timeout_inf": (("--trial-timeout", "inf"),
                                      "--trial-timeout: expected seconds > 0 and at most 1e+06, got inf"),
    "11_campaign_seed_negative": (("--seed", "-1"), "--seed: expected an integer in 0..4294967295, got -1"),
}
for _name, (_flags, _expect) in CAMPAIGN_FLAG_CASES.items():
    GENERATED[_name] = lambda tmp, flags=_flags, expect=_expect: (_campaign_argv(tmp, *flags), expect)


# item 9: files that are not regular files, or too large
@case("09_config_dev_zero")
def _(tmp: Path):
    return ["validate", MISSION, "--config", "/dev/zero"], "/dev/zero:1:1: is a character device, expected a YAML file"


#: what a file is made into: kind -> (maker, the problem reported at its line 1:1)
SPECIAL_FILES: dict[str, tuple[Callable[[Path], Path], str]] = {
    "fifo": (_fifo, "is a FIFO (named pipe), expected a YAML file"),
    "sparse_3g": (_sparse, "file is 3221225472 bytes, larger than the 4194304 byte limit"),
}


def _special_case(tmp: Path, role: str, kind: str) -> tuple[list[str | Path], str]:
    """The ``role`` file (mission, include, config, requests or world) made a ``kind``."""
    make, problem = SPECIAL_FILES[kind]
    f = make(tmp / f"{role}.yaml")
    if role == "mission":
        return ["validate", f], f"{f}:1:1: {problem}"
    if role == "include":
        m = _mission_including(tmp, f.name)
        return ["validate", m], f"{m}:2:12: include {f.name!r}: {problem}"
    if role == "config":
        return ["validate", MISSION, "--config", f], f"{f}:1:1: {problem}"
    if role == "requests":
        return _run_argv(tmp, "--requests", str(f)), f"{f}:1:1: {problem}"
    c = tmp / "sim.yaml"  # a sim world, named relative to the current folder
    c.write_text(f"backend: sim\nsim:\n  world: ./{f.name}\n")
    return ["run", MISSION, "--config", c, "--request", "x=1", "--log", tmp / "l.jsonl"], f"{f.name}:1:1: {problem}"


for _role in ("mission", "include", "config", "requests", "world"):
    for _kind in SPECIAL_FILES:
        GENERATED[f"09_{_role}_{_kind}"] = lambda tmp, role=_role, kind=_kind: _special_case(tmp, role, kind)


@case("09_config_sparse_5m")
def _(tmp: Path):
    f = _sparse(tmp / "c.yaml", 5 << 20)
    return ["validate", MISSION, "--config", f], f"{f}:1:1: file is 5242880 bytes, larger than the 4194304 byte limit"


@case("09_config_directory")
def _(tmp: Path):
    return ["validate", MISSION, "--config", tmp], f"{tmp}:1:1: is a directory, expected a YAML file"


# item 10: includes and worlds outside the allowed folders; the foreign file is never shown
def _foreign(tmp: Path) -> Path:
    outside = tmp / "outside"
    outside.mkdir()
    secret = outside / "secret.yaml"
    secret.write_text("SECRET-CONTENT: do not print me\n")
    return secret


@case("10_include_symlink_escape")
def _(tmp: Path):
    mission_dir = tmp / "missions"
    mission_dir.mkdir()
    (mission_dir / "innocent.yaml").symlink_to(_foreign(tmp))
    m = _mission_including(mission_dir, "innocent.yaml")
    return ["validate", m], f"{m}:2:12: include 'innocent.yaml': outside the folders a mission may include from"


@case("10_include_sibling_folder")
def _(tmp: Path):
    _foreign(tmp)
    mission_dir = tmp / "missions"
    mission_dir.mkdir()
    m = _mission_including(mission_dir, "../outside/secret.yaml")
    return ["validate", m], f"{m}:2:12: include '../outside/secret.yaml': outside the folders a mission may include from"


# item 11: symlink loops, a bad seed
@case("11_mission_symlink_loop")
def _(tmp: Path):
    (tmp / "a.yaml").symlink_to("b.yaml")
    (tmp / "b.yaml").symlink_to("a.yaml")
    return ["validate", tmp / "a.yaml"], f"{tmp / 'a.yaml'}:1:1: too many levels of symbolic links (a symlink loop?)"


@case("11_include_symlink_loop")
def _(tmp: Path):
    (tmp / "sub.yaml").symlink_to("sub.yaml")
    m = _mission_including(tmp, "sub.yaml")
    return ["validate", m], f"{m}:2:12: include 'sub.yaml': too many levels of symbolic links (a symlink loop?)"


@case("11_config_symlink_loop")
def _(tmp: Path):
    (tmp / "c.yaml").symlink_to("c.yaml")
    return ["validate", MISSION, "--config", tmp / "c.yaml"], "c.yaml:1:1: too many levels of symbolic links"


# item 12: a file name carrying an escape sequence
@case("12_escape_in_file_name")
def _(tmp: Path):
    return ["validate", tmp / "\x1b]0;owned\x07\x1b[2J.yaml"], "\\x1b]0;owned\\x07\\x1b[2J.yaml:1:1: no such file"


@pytest.mark.parametrize("name", sorted(GENERATED))
def test_generated_case(name: str, tmp_path: Path) -> None:
    argv, expect = GENERATED[name](tmp_path)
    res = mmexec(*argv, cwd=tmp_path)
    assert_one_located_line(res, expect)
    assert "SECRET" not in res.err + res.out


# --------------------------------------------------------------------------- what stays allowed


def test_roots_in_the_config_allow_an_outside_include(tmp_path: Path) -> None:
    """The confinement is a default, not a wall: a folder the config names in ``roots:``
    may be included from (relative to the config file), and so may the project's trees/."""
    shared = tmp_path / "shared"
    shared.mkdir()
    (shared / "pause.yaml").write_text("tree:\n  wait: 0.1\n")
    mission_dir = tmp_path / "missions"
    mission_dir.mkdir()
    m = mission_dir / "m.yaml"
    m.write_text("tree:\n  sequence:\n    - include: ../shared/pause.yaml\n"
                 f"    - include: {Path(__file__).parents[2] / 'trees' / 'fetch' / 'go_home.yaml'}\n")
    c = tmp_path / "c.yaml"
    c.write_text("backend: mock\nroots: [shared]\n")
    assert mmexec("validate", m, cwd=tmp_path).rc == 2
    res = mmexec("validate", m, "--config", c, cwd=tmp_path)
    assert res.rc == 0, res.err


# --------------------------------------------------------------------------- item 11: --watch


@pytest.mark.parametrize("how", ["fifo", "loop", "folder"])
def test_watch_keeps_serving_the_previous_version_when_the_mission_becomes_unreadable(tmp_path: Path,
                                                                                        how: str) -> None:
    """Request 1 replaces the mission file by a FIFO, a symlink loop or a folder: the
    reload before request 2 reports it on one line and requests 2 and 3 run the version
    already loaded; the run ends 0."""
    m = tmp_path / "m.yaml"
    m.write_text("requests:\n  item: {type: int}\ntree:\n  sequence:\n"
                 "    - skill: report\n      params: {message: \"v1 item {request.item}\"}\n"
                 f"    - skill: spoil_file\n      params: {{path: {str(m)!r}, how: {how}}}\n")
    c = tmp_path / "c.yaml"
    c.write_text("backend: mock\nskills:\n  modules: [hostile_skills]\n")
    res = mmexec("run", m, "--config", c, "--watch", "--request", "item=1", "--request", "item=2",
                 "--request", "item=3", "--log", tmp_path / "run.jsonl", cwd=tmp_path)
    assert res.rc == 0, res.err
    assert [ln.strip() for ln in res.out.splitlines() if "v1 item" in ln] == ["v1 item 1", "v1 item 2", "v1 item 3"]
    err = res.err.splitlines()
    assert len(err) == 2 and "changed but has errors; still running the previous version" in err[0], res.err
    assert err[1].startswith(f"{m}:1:1: "), err[1]


def test_a_skill_calling_sys_exit_during_a_run_fails_the_command(tmp_path: Path) -> None:
    """It exited 0 (the status user code passed to sys.exit), while the log said 1."""
    m = tmp_path / "m.yaml"
    m.write_text("tree:\n  skill: exit_now\n")
    c = tmp_path / "c.yaml"
    c.write_text("backend: mock\nskills:\n  modules: [hostile_skills]\n")
    log = tmp_path / "run.jsonl"
    res = mmexec("run", m, "--config", c, "--log", log, cwd=tmp_path)
    assert res.rc == 1, res.err
    expect = f"mmexec: a skill or skill module called sys.exit(0); the command was stopped (log: {log})"
    assert res.err.splitlines() == [expect]
    assert '"exit_code":1' in log.read_text().splitlines()[-1]


# --------------------------------------------------------------------------- item 12: output


def test_escape_sequences_in_user_text_never_reach_the_terminal(tmp_path: Path) -> None:
    """A report message and a failure reason full of escape sequences (clear screen,
    retitle the window, carriage return, a bidi override) are shown escaped by
    ``mmexec run`` and by ``mmexec log summary`` / ``replay`` of its log."""
    evil = "\\e[2J\\e]0;owned\\a\\rforged\\u202e"
    m = tmp_path / "m.yaml"
    m.write_text("tree:\n  sequence:\n"
                 f"    - skill: report\n      params: {{message: \"hello {evil}\"}}\n"
                 f"    - skill: fail_with\n      params: {{message: \"broke {evil}\"}}\n")
    c = tmp_path / "c.yaml"
    c.write_text("backend: mock\nskills:\n  modules: [hostile_skills]\n")
    log = tmp_path / "run.jsonl"
    run = mmexec("run", m, "--config", c, "--log", log, cwd=tmp_path)
    assert run.rc == 1, run.err
    shown = "\\x1b[2J\\x1b]0;owned\\x07\\rforged\\u202e"
    assert f"hello {shown}" in run.out and f"broke {shown}" in run.out
    summary = mmexec("log", "summary", log, cwd=tmp_path)
    replay = mmexec("log", "replay", log, cwd=tmp_path)
    assert f"broke {shown}" in summary.out
    for res in (run, summary, replay):
        assert not CONTROL.search(res.out + res.err), repr(res.out + res.err)
