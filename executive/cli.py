"""The ``mmexec`` command line (see docs/cli.md).

Exit codes:

* 0: success (``run``: every request succeeded);
* 1: ``run``: at least one request failed, timed out or raised; also a backend that
  failed to start for a reason outside the config (``mmexec: backend 'sim' failed to
  start: ...``, e.g. no display for ``--gui``) and internal errors;
* 2: bad input (missing file, bad YAML, bad config, profile or mission, a mission needing
  a capability the configured robot lacks, ``--gui`` / ``--record`` on a backend that
  cannot honour them, a configured device that cannot be brought up: no such port, no
  answer, located at its config section; bad ``--request``, unknown skill module, bad
  command line), with one line per problem on stderr and no traceback;
* 130, 143, 129: ``run`` halted by SIGINT (Ctrl-C, also during start-up), SIGTERM or
  SIGHUP (128 + the signal): the tree was halted, the robot left safe, the log ended;
  ``run`` also exits 1 when its event log cannot be written (disk full), the robot
  stopped, and 2 when ``--log`` exists (without ``--overwrite``) or cannot be used;
* 141: the reader of standard output went away (``mmexec show ... | head``): the
  command stopped writing and exited quietly (128 + SIGPIPE, as a Unix tool reports).

An unexpected exception prints ``mmexec: internal error: ...`` (one line, with the log
path when a run had started) and exits 1; ``MMEXEC_DEBUG=1`` shows the traceback.
"""

from __future__ import annotations

import sys

try:  # Ctrl-C while the command is still importing (a tenth of a second) exits 130 quietly too
    import argparse
    import contextlib
    import importlib.resources
    import logging
    import os
    from collections.abc import Iterator, Sequence
    from pathlib import Path
    from typing import Any, NoReturn

    from mmexec.config.brokenpipe import detach_stdout
    from mmexec.config.yamlload import (
        InputError,
        Mark,
        Problem,
        YDict,
        YList,
        did_you_mean,
        load_yaml,
    )
    from mmexec.executive.runner import SEED_RANGE, ArgMark, BackendStartError
    from mmexec.executive.textsafe import printable
except KeyboardInterrupt:
    print("mmexec: interrupted", file=sys.stderr)
    raise SystemExit(130) from None

__all__ = ["main"]

EXIT_OK, EXIT_FAILED, EXIT_INPUT, EXIT_INTERRUPTED = 0, 1, 2, 130

#: The requests ``mmexec demo`` serves (markers of the lab's boxes 3 and 5).
DEMO_REQUESTS: tuple[dict[str, str], ...] = ({"item": "3"}, {"item": "5"})
#: The requests ``mmexec demo --mock`` serves.
MOCK_DEMO_REQUESTS: tuple[dict[str, str], ...] = ({"item": "1"}, {"item": "2"})
#: Where ``mmexec demo`` writes its event log and video unless ``--out`` says otherwise.
DEMO_OUT = Path("out") / "demo"


class UsageError(Exception):
    """A bad command line (printed as one line, exit 2)."""


class UserCodeExit(Exception):
    """User code (a skill, a skill module) called ``sys.exit()`` while a command ran it
    (printed as one line, exit 1, as the run's event log records)."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        raise UsageError(f"{self.prog}: {message} (see '{self.prog} --help')")


def _parser() -> argparse.ArgumentParser:
    p = _Parser(prog="mmexec", description="Behaviour-tree mission executive for mobile manipulators.")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)

    v = sub.add_parser("validate", help="check a mission (exit 0 valid, 2 problems)")
    v.add_argument("mission", type=Path)
    v.add_argument("--config", type=Path, help="also load its skill modules and check the robot has what the skills need")

    k = sub.add_parser("skills", help="list the skills a mission can use: parameters, units, defaults, needs")
    k.add_argument("names", nargs="*", metavar="NAME", help="only these skills (default: all)")
    k.add_argument("--config", type=Path, help="also load this config's skill modules (skills.modules)")

    s = sub.add_parser("show", help="print the compiled tree; export it as Graphviz dot / SVG")
    s.add_argument("mission", type=Path)
    s.add_argument("--config", type=Path, help="load this config's skill modules first")
    s.add_argument("--dot", type=Path, metavar="FILE")
    s.add_argument("--svg", type=Path, metavar="FILE")

    r = sub.add_parser("run", help="serve requests with a mission on the configured backend")
    r.add_argument("mission", type=Path)
    r.add_argument("--config", type=Path, required=True)
    r.add_argument("--request", action="append", nargs="+", default=[], metavar="K=V",
                   help="one request (repeat the option for more); several K=V fields per request")
    r.add_argument("--requests", type=Path, metavar="FILE", help="YAML list of request mappings (served after --request ones)")
    _add_run_options(r)
    r.add_argument("--watch", action="store_true", help="reload the mission between requests when it changes")
    r.add_argument("--answers", type=Path, metavar="FILE",
                   help="YAML list of answers to ask_operator prompts, in order, or a sim_click: mapping "
                        "(a scripted operator clicking the true part in the sim) (default: ask on the terminal)")

    sv = sub.add_parser("serve", help="run the executive as a service: HTTP + WebSocket API, requests as they arrive")
    sv.add_argument("mission", type=Path)
    sv.add_argument("--config", type=Path, required=True)
    sv.add_argument("--bind", default="127.0.0.1:8765", metavar="HOST:PORT",
                    help="where the API listens (default 127.0.0.1:8765; off loopback every call needs the token)")
    _add_run_options(sv)

    lg = sub.add_parser("log", help="read an event log")
    lsub = lg.add_subparsers(dest="log_command", metavar="ACTION", parser_class=_Parser)
    ls = lsub.add_parser("summary", help="requests, outcomes, recoveries, durations, failure reasons")
    ls.add_argument("file", type=Path)
    lr = lsub.add_parser("replay", help="re-render the tree's states step by step")
    lr.add_argument("file", type=Path)
    lr.add_argument("--step", action="store_true", help="wait for Enter between steps")
    lr.add_argument("--request", type=int, metavar="N", help="only request N (1-based)")
    le = lsub.add_parser("export", help="convert the log into an MCAP file for Foxglove (events, log lines, tree)")
    le.add_argument("file", type=Path)
    le.add_argument("--mcap", type=Path, metavar="OUT", required=True, help="the MCAP file to write (a new file)")
    le.add_argument("--overwrite", action="store_true", help="replace an existing OUT (never a symlink)")

    from mmexec.executive.campaign import add_campaign_parser

    add_campaign_parser(sub)
    d = sub.add_parser("demo", help="run the embedded demo: the fetch mission in the headless simulator, two requests")
    d.add_argument("--out", type=Path, default=DEMO_OUT, metavar="DIR",
                   help=f"folder for the event log and the video (default {DEMO_OUT})")
    d.add_argument("--no-record", action="store_true", help="do not record the video")
    d.add_argument("--mock", action="store_true",
                   help="the small mock-backend demo instead (trees/demo_mock.yaml, no simulator)")
    sub.add_parser("hw", help="hardware bring-up tools (mmexec hw --help)", add_help=False)
    return p


def _add_run_options(p: argparse.ArgumentParser) -> None:
    """The options ``run`` and ``serve`` share."""
    p.add_argument("--param", action="append", default=[], metavar="K=V", help="override a mission parameter")
    p.add_argument("--seed", type=int)
    p.add_argument("--log", type=Path, metavar="FILE",
                   help="event log, a new file (default mmexec-logs/<mission>-<time>-<pid>.jsonl)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace an existing --log or --mcap file (never a symlink)")
    p.add_argument("--rate", type=float, metavar="HZ", help="tick rate, overrides the config's rate_hz")
    p.add_argument("--request-timeout", type=float, metavar="S", help="halt a request after S clock seconds")
    p.add_argument("--gui", action="store_true", help="show the simulator window (sim backend)")
    p.add_argument("--record", type=Path, metavar="FILE", help="record a video (sim backend)")
    p.add_argument("--no-recovery", action="store_true", help="disable every recovery node (ablation)")
    p.add_argument("--foxglove", nargs="?", const="127.0.0.1:8766", metavar="HOST:PORT",
                   help="serve the live state to Foxglove over WebSocket (default 127.0.0.1:8766)")
    p.add_argument("--mcap", type=Path, metavar="FILE",
                   help="record the run's Foxglove channels into a new MCAP file (docs/foxglove.md)")


# --------------------------------------------------------------------------- helpers


def _kv(token: str, what: str, mark: Mark) -> tuple[str, str]:
    key, sep, value = token.partition("=")
    if not sep or not key.strip():
        raise InputError.at(mark, f"{what}: expected KEY=VALUE, got {token!r}")
    return key.strip(), value


def _cli_requests(groups: Sequence[Sequence[str]]) -> list[Any]:
    from mmexec.executive.runner import Request

    out = []
    problems: list[Problem] = []
    for i, group in enumerate(groups, start=1):
        mark = ArgMark("--request", i, 1)
        fields: dict[str, str] = {}
        for tok in group:
            try:
                k, v = _kv(tok, "request", mark)
            except InputError as e:
                problems.extend(e.problems)
                continue
            if k in fields:
                problems.append(Problem(mark, f"request: field {k!r} given twice"))
            fields[k] = v
        out.append(Request(fields, mark))
    if problems:
        raise InputError(problems)
    return out


def _file_requests(path: Path) -> list[Any]:
    from mmexec.executive.runner import Request

    data = load_yaml(path)
    top = getattr(data, "mark", Mark(str(path), 1, 1))
    if not isinstance(data, YList):
        raise InputError.at(top, "expected a YAML list of request mappings, e.g. '- {item: 3}'")
    problems: list[Problem] = []
    out = []
    for i, item in enumerate(data):
        mark = data.item_mark(i)
        if not isinstance(item, YDict):
            problems.append(Problem(mark, f"request {i + 1}: expected a mapping of request fields, got {item!r}"))
            continue
        bad = [k for k, v in item.items() if isinstance(v, (dict, list))]
        for k in bad:
            problems.append(Problem(item.value_mark(k), f"request {i + 1}: field {k!r}: expected a scalar value"))
        out.append(Request(dict(item), mark))
    if problems:
        raise InputError(problems)
    return out


@contextlib.contextmanager
def _quiet_stderr_fd() -> Iterator[None]:
    """Silence file descriptor 2 (C-level prints such as pybullet's build banner)."""
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 2)
            try:
                yield
            finally:
                os.dup2(saved, 2)
    finally:
        os.close(saved)


def _preload_pybullet_quietly() -> None:
    """Import pybullet with its build banner suppressed, before the sim backend or the
    built-in arm skills (planning scene) import it, whatever the backend."""
    if "pybullet" in sys.modules:
        return
    try:
        with _quiet_stderr_fd():
            import pybullet  # noqa: F401
    except ImportError:
        return  # the backend factory reports the missing module properly


def _load_for_mission(config: Path | None, *, check_profile: bool = True) -> Any:
    from mmexec.executive.config import load_config, load_skill_modules

    _preload_pybullet_quietly()  # the sim backend and the built-in arm skills import pybullet: no banner
    loaded = load_config(config) if config is not None else None
    load_skill_modules(loaded, check=check_profile)
    return loaded


def _walk_specs(root: Any) -> Iterator[Any]:
    """Every NodeSpec reachable from ``root`` (children, options, included files)."""
    seen: set[int] = set()
    stack = [root]
    while stack:
        node = stack.pop()
        if node is None or id(node) in seen:
            continue
        seen.add(id(node))
        if hasattr(node, "kind") and hasattr(node, "mark"):
            yield node
            stack.extend(getattr(node, "children", []) or [])
            for value in (getattr(node, "opts", {}) or {}).values():
                items = value if isinstance(value, (list, tuple)) else [value]
                for it in items:
                    if hasattr(it, "kind") and hasattr(it, "mark"):
                        stack.append(it)
                    elif hasattr(it, "tree") and hasattr(it, "includes"):
                        stack.append(it.tree)


def _check_binding(mission: Any, loaded: Any) -> None:
    """InputError with every problem of binding ``mission`` to the config, all at once:
    a bad backend section, each skill leaf needing a capability the configured robot
    lacks, and the profile and its base poses on the robot's map
    (:func:`mmexec.executive.binding.binding_problems`). Nothing is opened: the backend
    finds its capabilities from its section alone
    (:meth:`~mmexec.executive.config.LoadedConfig.capabilities`; the robot backend's are its
    planned device slots, the sim's are fixed)."""
    from mmexec.executive.binding import binding_problems
    from mmexec.skills.base import SkillSpec

    _preload_pybullet_quietly()
    problems: list[Problem] = []
    try:
        caps: frozenset[str] | None = loaded.capabilities()
    except InputError as e:
        problems.extend(e.problems)
        caps = None
    for spec in _walk_specs(mission.root_file.tree) if caps is not None else ():
        skill = (getattr(spec, "opts", {}) or {}).get("skill")
        if not isinstance(skill, SkillSpec):
            continue
        for need in skill.needs:
            if need not in caps:
                problems.append(Problem(spec.mark, f"skill {skill.name!r} needs a {need}, and backend "
                                                   f"{loaded.backend!r} in {loaded.path} has none"))
    problems.extend(binding_problems(loaded))
    if problems:
        raise InputError(dict.fromkeys(problems))  # a bad section is found by both checks: once


# --------------------------------------------------------------------------- commands


#: Added to an unknown skill's problem when no ``--config`` was given: only the built-in
#: skills are known then.
_CONFIG_HINT = "; a skill from your own modules needs --config CONFIG (its skills.modules are loaded first)"


def _load_mission(args: argparse.Namespace, *, check_profile: bool = True) -> tuple[Any, Any]:
    """The config (None without ``--config``) with its skill modules loaded, and the
    mission; without ``--config`` an unknown skill's problem says to pass one."""
    from mmexec.executive.compiler import load_mission

    loaded = _load_for_mission(args.config, check_profile=check_profile)
    try:
        mission = load_mission(args.mission, roots=loaded.roots if loaded is not None else ())
    except InputError as e:
        if loaded is not None:
            raise
        raise InputError(Problem(p.mark, p.message + _CONFIG_HINT) if p.message.startswith("unknown skill ") else p
                         for p in e.problems) from None
    return loaded, mission


def _cmd_validate(args: argparse.Namespace) -> int:
    loaded, mission = _load_mission(args, check_profile=False)  # the binding check reports it with the rest
    if loaded is not None:
        _check_binding(mission, loaded)
    print(printable(f"{args.mission}: ok ({mission.node_count} nodes"
                    + (f", binds to backend {loaded.backend!r}" if loaded is not None else "") + ")"))
    return EXIT_OK


def _cmd_skills(args: argparse.Namespace) -> int:
    """``mmexec skills``: the skill catalogue (:mod:`mmexec.executive.catalog`)."""
    from mmexec.executive.catalog import catalogue
    from mmexec.skills.base import REGISTRY

    loaded = _load_for_mission(args.config, check_profile=False)  # listing needs the modules, not the profile
    problems = [Problem(ArgMark("mmexec skills", i, 1), f"unknown skill {name!r}{did_you_mean(name, REGISTRY.names())}"
                        + ("" if loaded is not None else _CONFIG_HINT))
                for i, name in enumerate(args.names, start=1) if name not in REGISTRY]
    if problems:
        raise InputError(problems)
    text = catalogue(REGISTRY, source=None if loaded is None else str(loaded.path), names=args.names or None)
    print(printable(text, multiline=True))
    return EXIT_OK


def _cmd_show(args: argparse.Namespace) -> int:
    import importlib

    try:
        display = importlib.import_module("mmexec.executive.display")
    except ModuleNotFoundError as e:
        if e.name != "mmexec.executive.display":
            raise
        raise UsageError("mmexec show: tree display is not available in this installation "
                         "(module mmexec.executive.display not found)") from None

    _, mission = _load_mission(args)
    tree = mission.display_tree()
    print(printable(display.render_text(tree), multiline=True))
    for path, writer in ((args.dot, display.write_dot), (args.svg, display.write_svg)):
        if path is None:
            continue
        try:
            writer(tree, path)
        except OSError as e:
            raise InputError.at(Mark(str(path), 1, 1), f"cannot write: {e.strerror or e}") from None
        print(f"wrote {path}")
    return EXIT_OK


def _check_run_flags(args: argparse.Namespace) -> None:
    """InputError, one line per bad flag, for a ``--seed`` outside :data:`SEED_RANGE`, a
    ``--rate`` outside the config's tick-rate range or a ``--request-timeout`` that is not
    finite, positive and within a mission's longest timeout (NaN and inf included)."""
    import math

    from mmexec.executive.config import MAX_RATE_HZ, MIN_RATE_HZ
    from mmexec.executive.schema import MAX_SECONDS

    problems: list[Problem] = []
    lo, hi = SEED_RANGE
    if args.seed is not None and not lo <= args.seed <= hi:
        problems.append(Problem(ArgMark("--seed", 0, 0), f"expected an integer in {lo}..{hi}, got {args.seed}"))
    if args.rate is not None and not (math.isfinite(args.rate) and MIN_RATE_HZ <= args.rate <= MAX_RATE_HZ):
        problems.append(Problem(ArgMark("--rate", 0, 0),
                                f"expected a tick rate in [{MIN_RATE_HZ:g}, {MAX_RATE_HZ:g}] Hz, got {args.rate:g}"))
    t = args.request_timeout
    if t is not None and not (math.isfinite(t) and 0 < t <= MAX_SECONDS):
        problems.append(Problem(ArgMark("--request-timeout", 0, 0),
                                f"expected clock seconds > 0 and at most {MAX_SECONDS:g}, got {t:g}"))
    if problems:
        raise InputError(problems)


def _run_options(mission: Path, config: Path, requests: list[Any], args: argparse.Namespace | None,
                 argv: Sequence[str]) -> Any:
    """The :class:`~mmexec.executive.runner.RunOptions` of ``run`` / ``serve`` (InputError)."""
    from mmexec.executive.runner import RunOptions

    params: dict[str, Any] = {}
    if args is not None:
        for i, tok in enumerate(args.param, start=1):
            k, v = _kv(tok, "param", ArgMark("--param", i, 1))
            params[k] = v
    opts = RunOptions(mission=mission, config=config, requests=requests, params=params, argv=list(argv))
    if args is not None:
        opts.seed, opts.log_path, opts.rate_hz = args.seed, args.log, args.rate
        opts.overwrite = getattr(args, "overwrite", False)
        opts.watch, opts.gui, opts.record = getattr(args, "watch", False), args.gui, args.record
        opts.request_timeout = args.request_timeout
        opts.recovery_enabled = not getattr(args, "no_recovery", False)
        _check_run_flags(args)
    return opts


def _check_params(runner: Any) -> None:
    """InputError (at ``--param``) when the mission refuses the ``--param`` values."""
    if runner.options.params:
        try:
            runner.mission.resolve_params(runner.options.params)
        except ValueError as e:
            raise InputError.at(ArgMark("--param", 1, 1), str(e)) from None


def _attach_operator(runner: Any, answers: Path | None) -> None:
    """Who answers ``ask_operator`` in ``run``: the ``--answers`` script, else the
    terminal when standard input is one, else nobody (the skill fails saying so)."""
    from mmexec.executive.serve.prompts import ScriptedAnswers, TerminalOperator, load_answers
    from mmexec.skills.operator import OPERATOR_KEY

    if answers is not None:
        from mmexec.executive.sim_operator import sim_click_operator

        sim = sim_click_operator(answers, lambda: runner.robot, runner.options.seed)  # a 'sim_click:' file
        runner.world[OPERATOR_KEY] = sim or ScriptedAnswers(load_answers(answers), answers)
    elif sys.stdin is not None and sys.stdin.isatty():
        term = TerminalOperator(sys.stdin.fileno(), sys.stderr, progress=runner.progress)
        runner.world[OPERATOR_KEY] = term
        runner.add_tick_hook(term.pace)


def _run(mission: Path, config: Path, requests: list[Any], args: argparse.Namespace | None,
         argv: Sequence[str]) -> int:
    from mmexec.executive.runner import Runner

    opts = _run_options(mission, config, requests, args, argv)
    recording = _recording(args)
    _preload_pybullet_quietly()
    runner = Runner(opts)
    runner.prepare()
    _check_params(runner)
    _attach_operator(runner, getattr(args, "answers", None))
    _CURRENT_LOG[0] = opts.log_path
    try:
        if recording is not None:
            recording.attach(runner)
            for line in recording.describe():
                print(line, flush=True)
        return runner.run()
    finally:
        _CURRENT_LOG[0] = runner.log_path
        if recording is not None:
            recording.close()


def _recording(args: argparse.Namespace | None) -> Any:
    """The ``--foxglove`` / ``--mcap`` outputs of ``run`` and ``serve`` (None: neither);
    a bad HOST:PORT is an InputError here, before anything is loaded."""
    foxglove, mcap = getattr(args, "foxglove", None), getattr(args, "mcap", None)
    if foxglove is None and mcap is None:
        return None
    from mmexec.executive.recording.session import Recording

    return Recording(foxglove=foxglove, mcap=mcap, overwrite=bool(getattr(args, "overwrite", False)))


def _cmd_run(args: argparse.Namespace, argv: Sequence[str]) -> int:
    requests = _cli_requests(args.request)
    if args.requests is not None:
        requests += _file_requests(args.requests)
    return _run(args.mission, args.config, requests, args, argv)


def _cmd_serve(args: argparse.Namespace, argv: Sequence[str]) -> int:
    """``mmexec serve``: see :mod:`mmexec.executive.serve.server` and docs/console.md."""
    try:
        from mmexec.executive.serve.server import serve
        from mmexec.executive.serve.service import ServeRunner
    except ModuleNotFoundError as e:
        if e.name not in ("fastapi", "uvicorn", "starlette", "pydantic"):
            raise
        raise UsageError(f"mmexec serve: needs the {e.name} package (pip install fastapi uvicorn)") from None
    opts = _run_options(args.mission, args.config, [], args, argv)
    recording = _recording(args)
    _preload_pybullet_quietly()
    _CURRENT_LOG[0] = opts.log_path
    runners: list[ServeRunner] = []

    def check(runner: ServeRunner) -> None:
        _check_params(runner)
        if recording is not None:
            recording.attach(runner)
            for line in recording.describe():
                runner.say(line)

    try:
        return serve(opts, args.bind, out=sys.stdout, err=sys.stderr, check=check, made=runners.append)
    finally:
        if runners:
            _CURRENT_LOG[0] = runners[0].log_path
        if recording is not None:
            recording.close()


def _cmd_demo(args: argparse.Namespace, argv: Sequence[str]) -> int:
    """``mmexec demo``: trees/fetch_item.yaml on config/locobot_sim.yaml (package data),
    headless, requests item=3 and item=5; the event log and a video go to ``--out``; a
    per-request table closes the output. ``--mock``: trees/demo_mock.yaml on the mock."""
    from mmexec.executive.runner import Request

    if args.mock:
        mission_res = importlib.resources.files("mmexec.trees").joinpath("demo_mock.yaml")
        config_res = importlib.resources.files("mmexec.config").joinpath("mock.yaml")
        with importlib.resources.as_file(mission_res) as mission, importlib.resources.as_file(config_res) as config:
            print(f"mmexec demo: {mission.name} on the mock backend ({config.name}), "
                  f"{len(MOCK_DEMO_REQUESTS)} requests")
            reqs = [Request(dict(r), ArgMark("demo request", i, 1)) for i, r in enumerate(MOCK_DEMO_REQUESTS, start=1)]
            ns = argparse.Namespace(param=[], seed=0, log=None, rate=None, watch=False, gui=False, record=None,
                                    request_timeout=None)
            return _run(mission, config, reqs, ns, argv)

    from mmexec.executive.runner import Runner, RunOptions

    out_dir: Path = args.out
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise InputError.at(Mark(str(out_dir), 1, 1), f"--out: cannot create the folder: {e.strerror or e}") from None
    log_path = out_dir / "events.jsonl"
    video = None if args.no_record else out_dir / "demo.mp4"
    mission_res = importlib.resources.files("mmexec.trees").joinpath("fetch_item.yaml")
    config_res = importlib.resources.files("mmexec.config").joinpath("locobot_sim.yaml")
    with importlib.resources.as_file(mission_res) as mission, importlib.resources.as_file(config_res) as config:
        print(f"mmexec demo: {mission.name} on the simulated LoCoBot ({config.name}, lab world, headless), "
              f"{len(DEMO_REQUESTS)} requests")
        reqs = [Request(dict(r), ArgMark("demo request", i, 1)) for i, r in enumerate(DEMO_REQUESTS, start=1)]
        # the demo's own folder: its previous events.jsonl is replaced (as its video is)
        opts = RunOptions(mission=mission, config=config, requests=reqs, seed=0, log_path=log_path,
                          overwrite=True, record=video, argv=list(argv))
        _preload_pybullet_quietly()
        runner = Runner(opts)
        runner.prepare()
        _CURRENT_LOG[0] = log_path
        code = runner.run()
    print()
    print(printable(demo_table(runner.results), multiline=True))
    print(f"event log: {log_path}")
    if video is not None:
        print(f"video: {video}")
    return code


def demo_table(results: Sequence[Any]) -> str:
    """The per-request table of ``mmexec demo``: request, result, clock time [s],
    recoveries used and failure reason, one row per
    :class:`~mmexec.executive.runner.RequestResult`."""
    head = ("request", "result", "clock s", "recoveries", "failure reason")
    rows = [(f"{r.index} ({', '.join(f'{k}={v}' for k, v in r.request.items())})", r.outcome, f"{r.duration:.1f}",
             str(r.recoveries), r.reason or "-") for r in results]
    widths = [max(len(head[i]), *(len(row[i]) for row in rows)) if rows else len(head[i]) for i in range(4)]
    lines = ["  ".join(h.ljust(w) for h, w in zip(head[:4], widths)) + "  " + head[4]]
    lines.append("  ".join("-" * w for w in widths) + "  " + "-" * len(head[4]))
    for row in rows:
        lines.append("  ".join(c.ljust(w) for c, w in zip(row[:4], widths)) + "  " + row[4])
    return "\n".join(lines)


def _cmd_log(args: argparse.Namespace) -> int:
    from mmexec.executive.eventlog import LogFormatError, read_log
    from mmexec.executive.logtools import NoSuchRequest, render_frame, replay_frames, summary

    try:
        records = read_log(args.file)
    except FileNotFoundError:
        raise InputError.at(Mark(str(args.file), 1, 1), "no such file") from None
    except IsADirectoryError:
        raise InputError.at(Mark(str(args.file), 1, 1), "is a directory, expected an event log") from None
    except OSError as e:  # unreadable, a path through a file, an I/O error
        raise InputError.at(Mark(str(args.file), 1, 1), f"cannot read: {e.strerror or e}") from None
    except LogFormatError as e:
        raise UsageError(str(e)) from None
    if args.log_command == "summary":
        print(printable(summary(records), multiline=True))  # a log holds user text (report messages, reasons)
        return EXIT_OK
    if args.log_command == "export":
        return _export(records, args)
    try:
        frames = replay_frames(records, request=args.request)
    except NoSuchRequest as e:
        raise InputError.at(ArgMark("--request", 0, 0), f"{e} ({args.file})") from None
    count = 0
    for frame in frames:
        if count:
            if args.step and sys.stdin.isatty():
                try:
                    input("[Enter: next step, Ctrl-D: stop] ")
                except EOFError:
                    print()
                    break
            print()
        print(printable(render_frame(frame), multiline=True))
        count += 1
    if count == 0:
        print("no node_status records to replay" + (f" for request {args.request}" if args.request else ""))
    return EXIT_OK


def _export(records: Sequence[dict[str, Any]], args: argparse.Namespace) -> int:
    """``mmexec log export LOG --mcap OUT``: see :mod:`mmexec.executive.recording.export`."""
    from mmexec.executive.recording.export import export_records
    from mmexec.executive.recording.session import open_mcap

    if args.mcap.resolve() == args.file.resolve():
        raise InputError.at(Mark(str(args.mcap), 1, 1), "--mcap: is the event log being exported")
    out = open_mcap(args.mcap, overwrite=args.overwrite)
    counts = export_records(records, out)
    if out.error is not None:
        raise InputError.at(Mark(str(args.mcap), 1, 1), f"--mcap: cannot write: {out.error.strerror or out.error}")
    filled = ", ".join(f"{topic} {n}" for topic, n in sorted(counts.items()))
    print(printable(f"wrote {args.mcap}: {sum(counts.values())} messages ({filled or 'none'})"))
    return EXIT_OK


def _cmd_hw(rest: Sequence[str]) -> int:
    import importlib

    try:
        hwcli = importlib.import_module("mmexec.drivers.hwcli")
    except ModuleNotFoundError as e:
        if e.name in ("mmexec.drivers.hwcli",):
            raise UsageError("mmexec hw: hardware tools are not available in this installation "
                             "(module mmexec.drivers.hwcli not found)") from None
        raise
    return int(hwcli.main(list(rest)))


_CURRENT_LOG: list[Path | None] = [None]


def _dispatch(argv: list[str]) -> int:
    if argv and argv[0] == "hw":
        return _cmd_hw(argv[1:])
    args = _parser().parse_args(argv)
    try:
        return _command(args, argv)
    except SystemExit as e:  # only user code raises it past the parser: not mmexec's exit status
        raise UserCodeExit(f"a skill or skill module called sys.exit({e.code!r}); the command was stopped") from None


def _command(args: argparse.Namespace, argv: list[str]) -> int:
    if args.command is None:
        _parser().print_help()
        return EXIT_INPUT
    if args.command == "validate":
        return _cmd_validate(args)
    if args.command == "show":
        return _cmd_show(args)
    if args.command == "skills":
        return _cmd_skills(args)
    if args.command == "run":
        return _cmd_run(args, argv)
    if args.command == "log":
        if args.log_command is None:
            raise UsageError("mmexec log: expected 'summary FILE', 'replay FILE' or 'export FILE --mcap OUT'")
        return _cmd_log(args)
    if args.command == "demo":
        return _cmd_demo(args, argv)
    if args.command == "serve":
        return _cmd_serve(args, argv)
    if args.command == "campaign":
        from mmexec.executive.campaign import cmd_campaign

        return cmd_campaign(args)
    raise UsageError(f"mmexec: unknown command {args.command!r}")


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``mmexec`` command; returns the exit code."""
    args = list(sys.argv[1:] if argv is None else argv)
    logging.basicConfig(level=logging.DEBUG if os.environ.get("MMEXEC_DEBUG") else logging.WARNING,
                        format="mmexec: %(levelname)s: %(name)s: %(message)s")
    _CURRENT_LOG[0] = None
    try:
        code = _dispatch(args)
        try:
            sys.stdout.flush()  # a reader that went away (`| head`) shows up here, not at exit
        except OSError:
            if code <= 128:
                raise
            detach_stdout()  # a run ended by a signal (SIGHUP: the terminal hung up, EIO) says so
        return code
    except BrokenPipeError:  # stdout's reader went away (`| head`): exit quietly
        return detach_stdout()
    except InputError as e:  # problems quote user text (keys, values, file names): escape it
        for p in e.problems:
            print(printable(p), file=sys.stderr)
        return EXIT_INPUT
    except UsageError as e:
        print(printable(e), file=sys.stderr)
        return EXIT_INPUT
    except BackendStartError as e:
        print(printable(f"mmexec: {e}"), file=sys.stderr)
        return EXIT_FAILED
    except UserCodeExit as e:
        where = f" (log: {_CURRENT_LOG[0]})" if _CURRENT_LOG[0] else ""
        print(printable(f"mmexec: {e}{where}"), file=sys.stderr)
        return EXIT_FAILED
    except KeyboardInterrupt:
        print("mmexec: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception as e:  # the documented last-resort boundary of the CLI
        if os.environ.get("MMEXEC_DEBUG"):
            raise
        where = f" (log: {_CURRENT_LOG[0]})" if _CURRENT_LOG[0] else ""
        msg = str(e).splitlines()[0] if str(e) else ""
        print(printable(f"mmexec: internal error: {type(e).__name__}: {msg}{where}; set MMEXEC_DEBUG=1 for details"),
              file=sys.stderr)
        return EXIT_FAILED
