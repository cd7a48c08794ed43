"""Campaigns: many randomized trials of one mission, with success statistics.

``mmexec campaign MISSION --config CONFIG --trials N --out DIR`` (docs/campaigns.md)
runs trial ``i`` (0-based) as one ``mmexec run`` process::

    mmexec run MISSION --config DIR/config.yaml --seed SEED_i [--request K=V ...]
               [--param K=V ...] [--request-timeout S] [--no-recovery] --log DIR/trials/NNNN.jsonl

so every trial is reproducible alone with the command recorded in ``DIR/trials.csv``
(the same line without ``--log``). Pieces:

* :func:`trial_seed`: ``SEED_i`` = the first 4 bytes (big-endian) of
  ``sha256(b"mmexec-campaign:<S>:<i>")``: independent-looking 32-bit seeds, stable across
  Python and numpy versions, computable by hand.
* ``DIR/config.yaml``: the config with the fault profile applied (:data:`FAULT_PROFILES`
  or a profile file; JSON-merge-patch semantics, :func:`merge_patch`) and, for the sim,
  ``randomize: true`` so each trial draws its world from the world's randomisation ranges
  with its seed.
* Requests (:class:`RequestPlan`): fixed (``--request``/``--requests``, the same for
  every trial) or drawn (``--draw FIELD=V1,V2,...`` or ``FIELD=@markers``, the marker
  ids of the sim world's items): trial ``i`` draws with ``random.Random(SEED_i)``.
* Execution: local processes (:class:`concurrent.futures.ProcessPoolExecutor`, spawn
  context, ``--workers`` of them) or Ray tasks (``--ray [ADDRESS]``); either way one
  worker runs one trial as a ``mmexec run`` subprocess (:func:`run_trial`), so a trial
  that crashes (a segfault in pybullet, ``os._exit`` in a skill, a SIGKILL) is one
  ``error`` row, its pybullet state dies with it, and the command in the CSV is exactly
  what ran.
* Results: ``DIR/trials/NNNN.json`` per finished trial (resume skips them), then
  ``summary.json``, ``trials.csv``, ``report.md`` and PNG plots
  (:mod:`mmexec.executive.campaign_report`).

Wall times here are measured with :func:`time.monotonic` (they describe the machine,
not the mission); mission times are clock seconds from the trials' event logs.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import copy
import dataclasses
import hashlib
import json
import logging
import math
import multiprocessing
import os
import random
import shlex
import signal
import subprocess
import sys
import time
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

from mmexec.config.yamlload import InputError, Mark, Problem, YDict, YList, load_yaml
from mmexec.executive.runner import SEED_RANGE, ArgMark, Progress
from mmexec.executive.values import MAX_SECONDS

__all__ = [
    "FAULT_PROFILES",
    "CampaignOptions",
    "FaultProfile",
    "RequestPlan",
    "TrialResult",
    "TrialSpec",
    "add_campaign_parser",
    "apply_fault_profile",
    "cmd_campaign",
    "load_fault_profile",
    "merge_patch",
    "parse_trial_log",
    "run_campaign",
    "run_trial",
    "trial_seed",
]

log = logging.getLogger(__name__)

#: The Python snippet each trial process runs (the ``mmexec`` entry point).
_ENTRY = "import sys; from mmexec.executive.cli import main; sys.exit(main())"


# --------------------------------------------------------------------------- seeds


def trial_seed(seed: int, index: int) -> int:
    """Seed of trial ``index`` (0-based) of a campaign with seed ``seed``: the first four
    bytes, big-endian, of ``sha256(f"mmexec-campaign:{seed}:{index}")``, in [0, 2**32)."""
    digest = hashlib.sha256(f"mmexec-campaign:{seed}:{index}".encode()).digest()
    return int.from_bytes(digest[:4], "big")


# --------------------------------------------------------------------------- fault profiles


def merge_patch(target: Any, patch: Any) -> Any:
    """RFC 7396 JSON merge patch: a mapping patch merges key by key (recursively), a
    ``None`` value deletes the key, anything else replaces the target. Returns a new
    value; ``target`` is not modified."""
    if not isinstance(patch, Mapping):
        return copy.deepcopy(patch)
    out: dict[str, Any] = dict(target) if isinstance(target, Mapping) else {}
    for key, value in patch.items():
        if value is None:
            out.pop(key, None)
        else:
            out[key] = merge_patch(out.get(key), value)
    return out


@dataclass(frozen=True)
class FaultProfile:
    """A named set of merge patches for backend sections of a run config.

    ``patches[backend]`` are applied in order to the config's ``<backend>:`` section
    (:func:`merge_patch`); a backend with no entry cannot run this profile.
    ``source`` is where it came from (``built-in`` or a file path)."""

    name: str
    description: str
    patches: Mapping[str, tuple[Mapping[str, Any], ...]]
    source: str = "built-in"


#: Patches that switch every injected fault off (the ``nominal`` profile's content).
_NOMINAL: dict[str, dict[str, Any]] = {
    "sim": {"faults": None},
    "mock": {"arm": {"fail_moves": None}, "gripper": {"grasps": None, "fault_moves": None},
             "base": {"blocked": None}, "camera": {"dropouts": None}},
}


def _profile(name: str, description: str, **specific: dict[str, Any]) -> FaultProfile:
    """Nominal plus one fault, for the backends that ``specific`` names (all backends
    with a nominal patch when it names none)."""
    backends = list(specific) or list(_NOMINAL)
    patches = {b: (_NOMINAL[b],) + ((specific[b],) if b in specific else ()) for b in backends}
    return FaultProfile(name, description, patches)


#: Built-in fault profiles (``--faults NAME``). Each starts from ``nominal`` (every fault
#: of the config off, noise as configured) and adds one fault. ``config`` (the default)
#: runs the config exactly as written.
FAULT_PROFILES: dict[str, FaultProfile] = {
    "config": FaultProfile("config", "the config's own faults section, unchanged",
                           {"sim": (), "mock": (), "robot": ()}),
    "nominal": _profile("nominal", "no injected faults; sensor and odometry noise as configured"),
    "arm_fail_first": _profile(
        "arm_fail_first", "the first arm attempt fails (sim: the first arm goal stops half-way and fails; "
                          "mock: the first grasp closes on nothing)",
        sim={"faults": {"arm_fail_attempts": [1]}}, mock={"gripper": {"grasps": [False]}}),
    "arm_fail_second": _profile(
        "arm_fail_second", "the second arm attempt fails (sim: arm goal 2, in fetch_item the pick's first move "
                           "after the initial tuck; mock: the second grasp)",
        sim={"faults": {"arm_fail_attempts": [2]}}, mock={"gripper": {"grasps": [True, False]}}),
    "arm_fail_twice": _profile(
        "arm_fail_twice", "the first two arm attempts fail (sim: arm goals 1 and 2; mock: grasps 1 and 2)",
        sim={"faults": {"arm_fail_attempts": [1, 2]}}, mock={"gripper": {"grasps": [False, False]}}),
    "arm_fail_always": _profile(
        "arm_fail_always", "every arm attempt fails (sim: every arm goal; mock: every grasp)",
        sim={"faults": {"arm_fail": "always"}}, mock={"gripper": {"default_grasp": False}}),
    "sensor_dropout": _profile(
        "sensor_dropout", "camera frames and lidar scans are missing with probability 0.2 (sim only)",
        sim={"faults": {"camera_dropout": {"p": 0.2}, "lidar_dropout": {"p": 0.2}}}),
    "nav_blocked": _profile(
        "nav_blocked", "the base cannot move (mock only; for the sim name the items in a profile file: "
                       "sim: {faults: {nav_blocked: [box_3]}})",
        mock={"base": {"blocked": True}}),
}


def _plain(value: Any) -> Any:
    """YDict/YList (and tuples) as plain dicts and lists, for JSON and YAML output."""
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def load_fault_profile(name_or_path: str) -> FaultProfile:
    """A built-in profile by name, or a profile file: a YAML mapping with optional
    ``description``, ``base: nominal|config`` (start from every fault off, the default,
    or from the config as written) and one merge patch per backend name (``sim:``,
    ``mock:``). InputError naming ``--faults`` or ``FILE:LINE:COL`` otherwise."""
    if name_or_path in FAULT_PROFILES:
        return FAULT_PROFILES[name_or_path]
    path = Path(name_or_path)
    if not (path.suffix in (".yaml", ".yml") or path.exists()):
        raise InputError.at(ArgMark("--faults", 0, 0), f"unknown fault profile {name_or_path!r} (built-in: "
                            f"{', '.join(FAULT_PROFILES)}; or a profile .yaml file)")
    raw = load_yaml(path)
    top = getattr(raw, "mark", Mark(str(path), 1, 1))
    if not isinstance(raw, YDict):
        raise InputError.at(top, "a fault profile is a mapping: {description: ..., sim: {faults: {...}}, mock: {...}}")
    problems: list[Problem] = []
    allowed = {"description", "base", "sim", "mock", "robot"}
    for key in raw:
        if key not in allowed:
            problems.append(Problem(raw.key_mark(key) if hasattr(raw, "key_mark") else top,
                                    f"unknown key {key!r} (expected: {', '.join(sorted(allowed))})"))
    base = raw.get("base", "nominal")
    if base not in ("nominal", "config"):
        problems.append(Problem(raw.value_mark("base"), f"base: expected 'nominal' or 'config', got {base!r}"))
    desc = raw.get("description", "")
    if not isinstance(desc, str):
        problems.append(Problem(raw.value_mark("description"), "description: expected a string"))
    patches: dict[str, tuple[Mapping[str, Any], ...]] = {}
    for backend in ("sim", "mock", "robot"):
        if backend not in raw:
            continue
        value = raw[backend]
        if not isinstance(value, YDict):
            problems.append(Problem(raw.value_mark(backend), f"{backend}: expected a mapping (a merge patch "
                                                             f"of the config's {backend}: section)"))
            continue
        start = (_NOMINAL[backend],) if base == "nominal" and backend in _NOMINAL else ()
        patches[backend] = start + (_plain(value),)
    if not patches and not problems:
        problems.append(Problem(top, "a fault profile needs at least one backend patch (sim:, mock: or robot:)"))
    if problems:
        raise InputError(problems)
    return FaultProfile(path.stem, str(desc), patches, source=str(path))


def apply_fault_profile(raw_config: Mapping[str, Any], profile: FaultProfile, *, randomize: bool) -> dict[str, Any]:
    """The config mapping with ``profile`` applied to its backend's section (and, for the
    sim, ``randomize`` set). InputError at ``--faults`` when the profile has nothing
    for the config's backend."""
    cfg = _plain(raw_config)
    backend = str(cfg.get("backend", ""))
    if backend not in profile.patches:
        raise InputError.at(ArgMark("--faults", 0, 0), f"fault profile {profile.name!r} has no patch for backend "
                            f"{backend!r} (it has: {', '.join(profile.patches) or 'none'})")
    section = cfg.get(backend) or {}
    for patch in profile.patches[backend]:
        section = merge_patch(section, patch)
    if backend == "sim":
        section["randomize"] = randomize
    if section or backend in cfg:
        cfg[backend] = section
    return cfg


# --------------------------------------------------------------------------- requests


@dataclass(frozen=True)
class RequestPlan:
    """How each trial's requests are chosen.

    ``fixed``: the same requests for every trial (each a mapping of field to value).
    ``draws``: ``{field: values}``: each trial serves ``per_trial`` requests, each field
    drawn uniformly from its values with ``random.Random(trial_seed)`` (fields in sorted
    order, one ``choice`` per field per request). Neither: one empty request."""

    fixed: tuple[Mapping[str, Any], ...] = ()
    draws: Mapping[str, tuple[Any, ...]] = field(default_factory=dict)
    per_trial: int = 1

    def requests_for(self, seed: int) -> list[dict[str, Any]]:
        if self.draws:
            rng = random.Random(seed)
            return [{k: rng.choice(self.draws[k]) for k in sorted(self.draws)} for _ in range(self.per_trial)]
        return [dict(r) for r in self.fixed] or [{}]

    def describe(self) -> str:
        if self.draws:
            parts = ", ".join(f"{k} from {list(v)}" for k, v in sorted(self.draws.items()))
            return f"{self.per_trial} request(s) per trial, {parts}, drawn with the trial seed"
        if self.fixed:
            return "fixed: " + "; ".join(", ".join(f"{k}={v}" for k, v in r.items()) or "-" for r in self.fixed)
        return "one empty request per trial"


def _cli_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


def _world_markers(cfg: Mapping[str, Any], mark: Mark) -> tuple[int, ...]:
    if cfg.get("backend") != "sim":
        raise InputError.at(mark, "@markers needs a sim config (the marker ids of the world's items)")
    from mmexec.sim.world import load_world

    world = load_world(str((cfg.get("sim") or {}).get("world", "lab")))
    return tuple(it.marker for it in world.spec.items)


def _parse_draws(tokens: Sequence[str], cfg: Mapping[str, Any]) -> dict[str, tuple[Any, ...]]:
    draws: dict[str, tuple[Any, ...]] = {}
    problems: list[Problem] = []
    for i, tok in enumerate(tokens, start=1):
        mark = ArgMark("--draw", i, 1)
        key, sep, value = tok.partition("=")
        key = key.strip()
        if not sep or not key or not value.strip():
            problems.append(Problem(mark, f"expected FIELD=V1,V2,... or FIELD=@markers, got {tok!r}"))
            continue
        if key in draws:
            problems.append(Problem(mark, f"field {key!r} drawn twice"))
            continue
        if value.strip() == "@markers":
            try:
                draws[key] = _world_markers(cfg, mark)
            except InputError as e:
                problems.extend(e.problems)
            continue
        values = tuple(v.strip() for v in value.split(",") if v.strip())
        if not values:
            problems.append(Problem(mark, f"no values to draw {key!r} from"))
            continue
        draws[key] = values
    if problems:
        raise InputError(problems)
    return draws


# --------------------------------------------------------------------------- trials


@dataclass(frozen=True)
class TrialSpec:
    """One trial to run: ``argv`` of ``mmexec`` (starting with ``run``), the event log it
    writes, where to run it (``cwd``), an optional wall-time limit [s] and where its
    console output goes."""

    index: int
    seed: int
    argv: tuple[str, ...]
    log_path: str
    out_path: str
    cwd: str
    wall_limit: float | None = None

    @property
    def command(self) -> str:
        """The shell command reproducing this trial alone (without ``--log`` and its
        ``--overwrite``)."""
        argv = list(self.argv)
        if "--log" in argv:
            i = argv.index("--log")
            del argv[i:i + 2]
        if "--overwrite" in argv:
            argv.remove("--overwrite")
        return shlex.join(["mmexec", *argv])


@dataclass
class TrialResult:
    """What one trial did. ``outcome``: ``success`` (every request succeeded),
    ``failure`` (a request failed or timed out), ``error`` (the trial process crashed,
    was killed, or a request raised), or ``interrupted`` (Ctrl-C; not recorded, re-run
    on resume). ``clock`` is the sum of its requests' durations [clock s], ``wall`` the
    trial process's wall time [s]."""

    index: int
    seed: int
    outcome: str
    clock: float
    wall: float
    recoveries: int
    reason: str
    failure_kind: str = ""
    failure_node: str = ""
    exit_code: int | None = None
    requests: list[dict[str, Any]] = field(default_factory=list)
    command: str = ""
    log: str = ""
    host: str = ""

    def to_json(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> TrialResult:
        names = {f.name for f in dataclasses.fields(cls)}
        return cls(**{k: v for k, v in data.items() if k in names})


def _signal_name(rc: int) -> str:
    try:
        return signal.Signals(-rc).name
    except ValueError:
        return f"signal {-rc}"


def parse_trial_log(spec: TrialSpec, *, exit_code: int | None, wall: float, note: str = "") -> TrialResult:
    """Turn a trial's event log (and how its process ended) into a :class:`TrialResult`.
    ``note`` is the reason to record if the process did not finish normally."""
    from mmexec.executive.eventlog import LogFormatError, read_log

    records: list[dict[str, Any]] = []
    problem = ""
    try:
        records = read_log(spec.log_path)
    except FileNotFoundError:
        problem = "no event log written"
    except LogFormatError as e:
        problem = f"unreadable event log: {e}"
    requests = [r for r in records if r.get("event") == "request_end"]
    run_end = next((r for r in records if r.get("event") == "run_end"), None)
    rows = [{"request": r.get("request", {}), "outcome": r.get("outcome", ""), "duration": float(r.get("duration", 0.0)),
             "recoveries": int(r.get("recoveries", 0)), "reason": r.get("reason", ""),
             "failure_kind": r.get("failure_kind", ""), "failure_node": r.get("failure_node", "")} for r in requests]
    clock = sum(r["duration"] for r in rows)
    recoveries = sum(r["recoveries"] for r in rows)
    common = {"index": spec.index, "seed": spec.seed, "clock": clock, "wall": wall, "recoveries": recoveries,
              "exit_code": exit_code, "requests": rows, "command": spec.command, "log": spec.log_path,
              "host": os.uname().nodename}
    if run_end is not None and run_end.get("outcome") == "interrupted":
        return TrialResult(outcome="interrupted", reason="interrupted (Ctrl-C)", **common)
    crashed = run_end is None or run_end.get("outcome") == "error" or exit_code not in (0, 1)
    if crashed:
        if note:
            reason = note
        elif exit_code is not None and exit_code < 0:
            reason = f"trial process killed by {_signal_name(exit_code)}"
        elif run_end is not None and run_end.get("error"):
            reason = f"run ended with an error: {run_end.get('error')}"
        else:
            reason = f"trial process exited with code {exit_code}"
            if run_end is None:
                reason += " before its run_end record"
        if problem:
            reason += f" ({problem})"
        return TrialResult(outcome="error", reason=reason, **common)
    bad = next((r for r in rows if r["outcome"] != "success"), None)
    if bad is None and len(rows) == int(run_end.get("requests", len(rows))):
        return TrialResult(outcome="success", reason="", **common)
    if bad is None:
        return TrialResult(outcome="error", reason="not every request was served", **common)
    reason = bad["reason"] or bad["outcome"]
    outcome = "error" if bad["outcome"] == "error" else "failure"
    return TrialResult(outcome=outcome, reason=reason, failure_kind=bad["failure_kind"],
                       failure_node=bad["failure_node"], **common)


def _tail(path: str, lines: int = 3) -> str:
    try:
        text = Path(path).read_text(errors="replace")
    except OSError as e:
        return f"<no output: {e.strerror}>"
    kept = [ln for ln in text.splitlines() if ln.strip()]
    return " | ".join(kept[-lines:])


#: Wall seconds an interrupted trial gets to stop before it is killed.
STOP_GRACE = 10.0


def _stop_trial(proc: subprocess.Popen[bytes]) -> None:
    """SIGINT the trial's process group, wait up to :data:`STOP_GRACE`, then SIGKILL it."""
    try:
        os.killpg(proc.pid, signal.SIGINT)
        proc.wait(timeout=STOP_GRACE)
    except subprocess.TimeoutExpired:
        log.warning("trial process %d still running %g s after SIGINT; killing it", proc.pid, STOP_GRACE)
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    except ProcessLookupError:
        log.debug("trial process %d already gone", proc.pid)


def run_trial(spec: TrialSpec) -> TrialResult:
    """Run one trial as a ``mmexec run`` subprocess (in a pool worker or a Ray task) and
    parse its event log. Never raises for what the trial does: a crash, a kill or a
    wall-time overrun is an ``error`` result; exit code 2 (bad input) is an ``error``
    whose reason holds the trial's own error lines."""
    Path(spec.log_path).parent.mkdir(parents=True, exist_ok=True)
    cmd = [sys.executable, "-c", _ENTRY, *spec.argv]
    t0 = time.monotonic()
    note = ""
    with open(spec.out_path, "wb") as out:
        proc = subprocess.Popen(cmd, cwd=spec.cwd, stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                start_new_session=True)
        try:
            rc: int | None = proc.wait(timeout=spec.wall_limit)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
            rc = proc.returncode
            note = f"killed after {spec.wall_limit:g} s of wall time (--trial-timeout)"
        except BaseException:
            # Ctrl-C (or a cancelled Ray task): the trial runs in its own session, so pass
            # the interrupt on; `mmexec run` halts its tree, leaves the robot safe and
            # writes run_end (interrupted). Past the grace period it is killed.
            _stop_trial(proc)
            raise
    wall = time.monotonic() - t0
    if not note and rc == 2:
        note = f"bad input: {_tail(spec.out_path, 5)}"
    elif not note and rc is not None and rc > 1:
        note = f"trial process exited with code {rc}: {_tail(spec.out_path)}"
    return parse_trial_log(spec, exit_code=rc, wall=wall, note=note)


# --------------------------------------------------------------------------- the campaign


@dataclass
class CampaignOptions:
    """What ``mmexec campaign`` was asked to do (paths as the user gave them)."""

    mission: Path
    config: Path
    trials: int
    out: Path
    seed: int = 0
    workers: int | None = None
    ray: str | None = None
    faults: str = "config"
    recovery: bool = True
    randomize: bool = True
    requests: RequestPlan = field(default_factory=RequestPlan)
    params: dict[str, str] = field(default_factory=dict)
    request_timeout: float | None = None
    trial_timeout: float | None = None
    compare: list[Path] = field(default_factory=list)
    progress: bool | None = None


#: Settings that must match for a DIR to be resumed (the identity of its trials).
_IDENTITY_KEYS = ("mission", "mission_sha256", "config", "config_sha256", "seed", "faults", "faults_patches",
                  "recovery", "randomize", "requests", "params", "request_timeout")


def _write_json(path: Path, data: Any) -> None:
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(json.dumps(data, indent=2, sort_keys=True) + "\n")
    os.replace(tmp, path)


def _dump_config(cfg: Mapping[str, Any], path: Path, header: str) -> None:
    import yaml  # writing only; all reading goes through mmexec.config.yamlload

    text = yaml.safe_dump(_plain(cfg), sort_keys=False, default_flow_style=None)
    path.write_text(header + text)


class Campaign:
    """Prepares, runs (resuming) and reports one campaign (see the module doc)."""

    def __init__(self, options: CampaignOptions, *, out: TextIO | None = None) -> None:
        self.options = options
        self.out = out if out is not None else sys.stdout
        self.dir = options.out
        self.trials_dir = self.dir / "trials"
        self.config_path = self.dir / "config.yaml"
        self.identity: dict[str, Any] = {}
        self.specs: list[TrialSpec] = []
        self.ran = 0

    # ------------------------------------------------------------------ prepare

    def prepare(self) -> None:
        """Check every input, write DIR/config.yaml and DIR/campaign.json, build the
        trial specs. Raises InputError on bad input or a DIR holding other settings."""
        from mmexec.executive.config import load_config
        from mmexec.executive.runner import Request, Runner, RunOptions

        o = self.options
        if o.trials < 1:
            raise InputError.at(ArgMark("--trials", 0, 0), f"expected at least 1 trial, got {o.trials}")
        if o.workers is not None and o.workers < 1:
            raise InputError.at(ArgMark("--workers", 0, 0), f"expected at least 1 worker, got {o.workers}")
        lo, hi = SEED_RANGE
        if not lo <= o.seed <= hi:
            raise InputError.at(ArgMark("--seed", 0, 0), f"expected an integer in {lo}..{hi}, got {o.seed}")
        for name, value in (("--request-timeout", o.request_timeout), ("--trial-timeout", o.trial_timeout)):
            # NaN and inf too: a NaN timeout never fires, an infinite one is no timeout
            if value is not None and not (math.isfinite(value) and 0 < value <= MAX_SECONDS):
                raise InputError.at(ArgMark(name, 0, 0), f"expected seconds > 0 and at most {MAX_SECONDS:g}, got {value:g}")
        for other in o.compare:
            if not (other / "summary.json").is_file():
                raise InputError.at(ArgMark("--compare", 0, 0), f"{other}: no summary.json (not a campaign directory)")
        loaded = load_config(o.config)
        profile = load_fault_profile(o.faults)
        cfg = apply_fault_profile(loaded.raw, profile, randomize=o.randomize)
        try:
            self.dir.mkdir(parents=True, exist_ok=True)
            self.trials_dir.mkdir(exist_ok=True)
        except OSError as e:
            raise InputError.at(ArgMark("--out", 0, 0), f"{self.dir}: cannot create: {e.strerror or e}") from None
        header = (f"# Generated by mmexec campaign from {o.config} (sha256 {loaded.sha256[:12]}) with fault profile "
                  f"{profile.name!r} ({profile.source})" + (", randomize on" if cfg.get("backend") == "sim"
                                                            and o.randomize else "") + ".\n")
        staged = self.dir / "config.yaml.new"
        _dump_config(cfg, staged, header)
        plan = o.requests
        _quiet_import_pybullet()
        # Preflight with the runner itself: config (as trials will see it), skill modules,
        # mission, every trial's requests; nothing is connected.
        seeds = [trial_seed(o.seed, i) for i in range(o.trials)]
        per_trial = [plan.requests_for(s) for s in seeds]
        # each distinct request once, located at the option it came from
        distinct: dict[str, Request] = {}
        for i, reqs in enumerate(per_trial):
            for j, r in enumerate(reqs):
                key = json.dumps({k: _cli_value(v) for k, v in r.items()}, sort_keys=True)
                if key not in distinct and (r or not plan.draws):
                    where = (ArgMark(f"--draw (trial {i:04d})", 0, 0) if plan.draws
                             else ArgMark("--request/--requests", j + 1, 1) if plan.fixed
                             else ArgMark("mmexec campaign (no --request or --draw given)", 0, 0))
                    distinct[key] = Request({k: _cli_value(v) for k, v in r.items()}, where)
        probe = Runner(RunOptions(mission=o.mission, config=staged, requests=list(distinct.values())))
        try:
            probe.prepare()
            if o.params:
                try:
                    probe.mission.resolve_params(dict(o.params))
                except ValueError as e:
                    raise InputError.at(ArgMark("--param", 1, 1), str(e)) from None
        except InputError:
            staged.unlink(missing_ok=True)
            raise
        identity = {
            "mission": str(o.mission),
            "mission_sha256": probe.mission.sha256,
            "config": str(o.config),
            "config_sha256": loaded.sha256,
            "seed": o.seed,
            "faults": profile.name,
            "faults_patches": _plain(profile.patches.get(str(cfg.get("backend")), ())),
            "faults_description": profile.description,
            "recovery": o.recovery,
            "randomize": o.randomize if cfg.get("backend") == "sim" else None,
            "requests": {"fixed": _plain(plan.fixed), "draws": _plain(plan.draws), "per_trial": plan.per_trial},
            "requests_description": plan.describe(),
            "params": dict(o.params),
            "request_timeout": o.request_timeout,
            "backend": cfg.get("backend"),
        }
        self._check_resume(identity)
        os.replace(staged, self.config_path)
        identity["trials"] = max(o.trials, int(self.identity.get("trials", 0) or 0))
        self.identity = identity
        _write_json(self.dir / "campaign.json", identity)
        cwd = str(Path.cwd())
        self.specs = [self._spec(i, seeds[i], per_trial[i], cwd) for i in range(o.trials)]

    def _check_resume(self, identity: Mapping[str, Any]) -> None:
        path = self.dir / "campaign.json"
        if not path.exists():
            return
        try:
            old = json.loads(path.read_text())
        except (OSError, ValueError) as e:
            raise InputError.at(ArgMark("--out", 0, 0), f"{path}: unreadable ({e}); use another --out") from None
        diffs = [f"{k}: {old.get(k)!r} there, {identity.get(k)!r} now" for k in _IDENTITY_KEYS
                 if _plain(old.get(k)) != _plain(identity.get(k))]
        if diffs:
            (self.dir / "config.yaml.new").unlink(missing_ok=True)
            raise InputError.at(ArgMark("--out", 0, 0), f"{self.dir} holds a campaign with other settings "
                                f"({'; '.join(diffs[:3])}); use another --out to compare them")
        self.identity = dict(old)

    def _spec(self, index: int, seed: int, requests: list[dict[str, Any]], cwd: str) -> TrialSpec:
        o = self.options
        argv = ["run", str(o.mission), "--config", str(self.config_path), "--seed", str(seed)]
        for r in requests:
            if r:
                argv += ["--request", *(f"{k}={_cli_value(v)}" for k, v in r.items())]
        for k, v in o.params.items():
            argv += ["--param", f"{k}={v}"]
        if o.request_timeout is not None:
            argv += ["--request-timeout", f"{o.request_timeout:g}"]
        if not o.recovery:
            argv.append("--no-recovery")
        log_path = self.trials_dir / f"{index:04d}.jsonl"
        # --overwrite: a resumed campaign runs an interrupted trial again into its own log
        argv += ["--log", str(log_path), "--overwrite"]
        return TrialSpec(index, seed, tuple(argv), str(log_path), str(self.trials_dir / f"{index:04d}.out"),
                         cwd, o.trial_timeout)

    # ------------------------------------------------------------------ resume

    def finished(self, spec: TrialSpec) -> TrialResult | None:
        """The recorded result of ``spec`` if it already ran in this DIR: its
        ``NNNN.json`` row, or (the row lost) an event log with a ``run_end`` record."""
        row = self.trials_dir / f"{spec.index:04d}.json"
        if row.exists():
            try:
                return TrialResult.from_json(json.loads(row.read_text()))
            except (OSError, ValueError, TypeError) as e:
                log.warning("%s: unreadable result row (%s); running the trial again", row, e)
                return None
        logp = Path(spec.log_path)
        if logp.exists():
            from mmexec.executive.eventlog import LogFormatError, read_log

            try:
                records = read_log(logp)
            except LogFormatError as e:
                log.warning("%s: %s; running the trial again", logp, e)
                return None
            run_end = next((r for r in records if r.get("event") == "run_end"), None)
            if run_end is not None and run_end.get("outcome") != "interrupted":
                result = parse_trial_log(spec, exit_code=run_end.get("exit_code"), wall=float("nan"))
                self._record(result)
                return result
        return None

    def _record(self, result: TrialResult) -> None:
        _write_json(self.trials_dir / f"{result.index:04d}.json", result.to_json())

    # ------------------------------------------------------------------ run

    def run(self) -> list[TrialResult]:
        """Run every trial not finished yet; returns all N results in trial order."""
        done: dict[int, TrialResult] = {}
        pending: list[TrialSpec] = []
        for spec in self.specs:
            prev = self.finished(spec)
            if prev is not None:
                done[spec.index] = prev
            else:
                pending.append(spec)
        o = self.options
        workers = o.workers or os.cpu_count() or 1
        where = f"Ray ({o.ray or 'local'})" if o.ray is not None else f"{min(workers, max(1, len(pending)))} local processes"
        self.say(f"campaign {self.dir}: {len(self.specs)} trials ({len(done)} already done, {len(pending)} to run "
                  f"on {where}); fault profile {self.identity.get('faults')}, recovery "
                  f"{'on' if o.recovery else 'off'}, seed {o.seed}")
        progress = _CampaignProgress(self.out, total=len(self.specs), done=list(done.values()),
                                     enabled=o.progress)
        if pending:
            runner = _run_ray if o.ray is not None else _run_local
            for result in runner(pending, workers, o.ray):
                if result.outcome == "interrupted":
                    continue
                self._record(result)
                done[result.index] = result
                self.ran += 1
                progress.add(result)
        progress.finish()
        return [done[s.index] for s in self.specs if s.index in done]

    def say(self, line: str) -> None:
        """Write one line of user-facing output."""
        self.out.write(line + "\n")
        self.out.flush()


def _input_error_from_trial(result: TrialResult) -> InputError:
    text = result.reason.removeprefix("bad input: ")
    return InputError.at(ArgMark(f"trial {result.index:04d}", 0, 0), f"{text} (command: {result.command})")


def _silence_stderr() -> None:
    """Pool worker initializer: point file descriptor 2 at /dev/null, so C-level banners
    (pybullet's build line) printed while a worker imports do not reach the console.
    Trials write their own output to DIR/trials/NNNN.out; worker exceptions come back
    through the futures."""
    fd = os.open(os.devnull, os.O_WRONLY)
    os.dup2(fd, 2)
    os.close(fd)


def _quiet_import_pybullet() -> None:
    """Import pybullet (if installed) with its build banner silenced, before the
    preflight loads skill modules that import it."""
    if "pybullet" in sys.modules:
        return
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        _silence_stderr()
        try:
            import pybullet  # noqa: F401
        except ImportError:
            log.debug("pybullet not installed; sim trials will report it")
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def _run_local(specs: Sequence[TrialSpec], workers: int, _address: str | None) -> Iterable[TrialResult]:
    """Trials on a spawn-context ProcessPoolExecutor, yielded as they finish."""
    ctx = multiprocessing.get_context("spawn")
    pool = concurrent.futures.ProcessPoolExecutor(max_workers=max(1, min(workers, len(specs))), mp_context=ctx,
                                               initializer=_silence_stderr)
    futures = {pool.submit(run_trial, s): s for s in specs}
    try:
        for fut in concurrent.futures.as_completed(futures):
            spec = futures[fut]
            try:
                result = fut.result()
            except concurrent.futures.process.BrokenProcessPool as e:
                result = parse_trial_log(spec, exit_code=None, wall=float("nan"),
                                         note=f"worker process died: {e}")
            if result.exit_code == 2:
                raise _input_error_from_trial(result)
            yield result
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


#: Ray reads this when it is imported: "0" selects its single-machine mode (its default on
#: macOS and Windows), where the node's address is 127.0.0.1 and every server of a local
#: instance (GCS, raylet, workers, agents) listens on loopback only. On Linux Ray
#: otherwise takes the machine's routable address and listens on all interfaces.
RAY_SINGLE_MACHINE_ENV = "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"
#: The only address a local Ray instance started for a campaign may listen on.
LOOPBACK = "127.0.0.1"


def _import_ray(*, local: bool) -> Any:
    """Import Ray. ``local`` (``--ray`` without an address): select Ray's single-machine
    mode first (:data:`RAY_SINGLE_MACHINE_ENV`), so the instance started for the campaign
    listens on 127.0.0.1 only; a cluster address is left to Ray."""
    if local:
        os.environ[RAY_SINGLE_MACHINE_ENV] = "0"
    try:
        import ray
    except ImportError:
        raise InputError.at(ArgMark("--ray", 0, 0), "Ray is not installed in this environment "
                            "(pip install 'ray>=2.9'); run without --ray for local processes") from None
    return ray


def _ray_init(ray: Any, workers: int, address: str | None) -> bool:
    """Connect to the cluster at ``address`` or, for ``""``, start a local instance with
    ``workers`` CPUs that listens on 127.0.0.1 only, unless Ray is initialised already
    (then the caller's instance is used). Returns True when this call initialised Ray
    (the caller shuts it down). A local instance on another address (Ray imported in this
    process before :func:`_import_ray` could select loopback) is shut down again and is
    an InputError naming ``--ray``."""
    if ray.is_initialized():
        return False
    env = {k: os.environ[k] for k in ("PYTHONPATH", "MMEXEC_DEBUG") if k in os.environ}
    kwargs: dict[str, Any] = {"include_dashboard": False, "log_to_driver": False, "configure_logging": False}
    if env:
        kwargs["runtime_env"] = {"env_vars": env}
    if address:
        ray.init(address=address, **kwargs)
        return True
    ray.init(num_cpus=max(1, workers), **kwargs)
    node = ray.util.get_node_ip_address()
    if node != LOOPBACK:
        ray.shutdown()
        raise InputError.at(ArgMark("--ray", 0, 0), f"a local Ray instance would listen on {node}, not {LOOPBACK} "
                            f"(Ray was imported before {RAY_SINGLE_MACHINE_ENV}=0 could be set); set it in the "
                            "environment, or start a cluster yourself and pass its address")
    return True


def _run_ray(specs: Sequence[TrialSpec], workers: int, address: str | None) -> Iterable[TrialResult]:
    """Trials as Ray tasks (one CPU each) on the cluster at ``address`` or, for ``""``,
    on a local Ray instance started for this campaign (``workers`` CPUs, listening on
    127.0.0.1 only: :func:`_ray_init`)."""
    ray = _import_ray(local=not address)
    started = _ray_init(ray, workers, address)
    try:
        task = ray.remote(num_cpus=1, max_retries=0)(run_trial)
        refs = {task.remote(s): s for s in specs}
        waiting = list(refs)
        try:
            yield from _ray_results(ray, refs, waiting)
        except KeyboardInterrupt:
            # cancel raises KeyboardInterrupt inside running tasks: they pass it to their trial
            for ref in waiting:
                ray.cancel(ref)
            ray.wait(waiting, num_returns=len(waiting), timeout=STOP_GRACE + 5.0)
            raise
    finally:
        if started:
            ray.shutdown()


def _ray_results(ray: Any, refs: Mapping[Any, TrialSpec], waiting: list[Any]) -> Iterable[TrialResult]:
    """Yield results as Ray tasks finish; ``waiting`` (the refs not finished) is updated
    in place so the caller can cancel what is left."""
    while waiting:
        ready, rest = ray.wait(waiting, num_returns=1)
        waiting[:] = rest
        for ref in ready:
            spec = refs[ref]
            try:
                result = ray.get(ref)
            except ray.exceptions.RayError as e:
                msg = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
                result = parse_trial_log(spec, exit_code=None, wall=float("nan"),
                                         note=f"Ray task failed: {type(e).__name__}: {msg}")
            if result.exit_code == 2:
                for r in waiting:
                    ray.cancel(r, force=True)
                raise _input_error_from_trial(result)
            yield result


class _CampaignProgress:
    """Trials done, successes so far and an ETA: one redrawn line on a terminal, a plain
    line per finished trial otherwise."""

    def __init__(self, stream: TextIO, *, total: int, done: list[TrialResult], enabled: bool | None) -> None:
        self.stream = stream
        self.total = total
        self.results = list(done)
        self.start_done = len(done)
        self.t0 = time.monotonic()
        self.tty = stream.isatty() if enabled is None else enabled
        self.line = Progress(stream, enabled=self.tty, interval=0.0)

    def _status(self) -> str:
        n = len(self.results)
        ok = sum(r.outcome == "success" for r in self.results)
        errors = sum(r.outcome == "error" for r in self.results)
        elapsed = time.monotonic() - self.t0
        ran = n - self.start_done
        eta = "-" if ran == 0 else _hms(elapsed / ran * (self.total - n))
        rate = f"{100.0 * ok / n:.1f}%" if n else "-"
        return (f"[{n}/{self.total}] {ok} ok ({rate})" + (f", {errors} errors" if errors else "")
                + f", elapsed {_hms(elapsed)}, ETA {eta}")

    def add(self, r: TrialResult) -> None:
        self.results.append(r)
        if self.tty:
            self.line.update(self._status(), force=True)
        else:
            why = f": {r.reason}" if r.reason else ""
            self.stream.write(f"trial {r.index:04d} seed {r.seed}: {r.outcome}, {r.clock:.1f} s clock, "
                              f"{r.wall:.1f} s wall{why}  {self._status()}\n")
            self.stream.flush()

    def finish(self) -> None:
        self.line.clear()


def _hms(seconds: float) -> str:
    s = round(seconds)
    h, rem = divmod(s, 3600)
    m, s = divmod(rem, 60)
    return f"{h}h{m:02d}m" if h else (f"{m}m{s:02d}s" if m else f"{s}s")


def run_campaign(options: CampaignOptions, *, out: TextIO | None = None) -> tuple[Campaign, list[TrialResult]]:
    """Prepare and run a campaign, then write summary.json, trials.csv, report.md and the
    plots. Returns the campaign and its results (trial order)."""
    from mmexec.executive.campaign_report import write_outputs

    campaign = Campaign(options, out=out)
    campaign.prepare()
    results = campaign.run()
    summary = write_outputs(campaign.dir, campaign.identity, results, compare=options.compare)
    campaign.say(
        f"{summary['successes']}/{summary['trials']} trials succeeded (success rate "
        f"{summary['success_rate']:.3f}, 95% CI {summary['success_rate_ci95'][0]:.3f}-"
        f"{summary['success_rate_ci95'][1]:.3f}), {summary['errors']} errors; report: {campaign.dir / 'report.md'}"
    )
    return campaign, results


# --------------------------------------------------------------------------- CLI


def add_campaign_parser(sub: Any) -> None:
    """Add the ``campaign`` subcommand to ``mmexec``'s subparsers."""
    c = sub.add_parser("campaign", help="run many randomized trials and report success statistics "
                                        "(docs/campaigns.md)")
    c.add_argument("mission", type=Path)
    c.add_argument("--config", type=Path, required=True)
    c.add_argument("--trials", type=int, required=True, metavar="N")
    c.add_argument("--out", type=Path, required=True, metavar="DIR",
                   help="campaign directory (re-running with the same DIR resumes)")
    c.add_argument("--seed", type=int, default=0, metavar="S", help="campaign seed (trial seeds derive from it)")
    c.add_argument("--workers", type=int, metavar="K", help="parallel trials (default: CPU count)")
    c.add_argument("--ray", nargs="?", const="", default=None, metavar="ADDRESS",
                   help="run trials as Ray tasks: on the cluster at ADDRESS, or a local Ray instance")
    c.add_argument("--faults", default="config", metavar="PROFILE",
                   help=f"fault profile: {', '.join(FAULT_PROFILES)} or a profile .yaml file (default config)")
    c.add_argument("--no-recovery", action="store_true", help="disable every recovery node (ablation)")
    c.add_argument("--no-randomize", action="store_true", help="sim: keep the world's nominal poses")
    c.add_argument("--request", action="append", nargs="+", default=[], metavar="K=V",
                   help="a fixed request served by every trial (repeat for more)")
    c.add_argument("--requests", type=Path, metavar="FILE", help="YAML list of fixed requests")
    c.add_argument("--draw", action="append", default=[], metavar="FIELD=V1,V2|@markers",
                   help="draw a request field per trial from these values (@markers: the sim world's items)")
    c.add_argument("--requests-per-trial", type=int, default=1, metavar="R", help="drawn requests per trial")
    c.add_argument("--param", action="append", default=[], metavar="K=V", help="override a mission parameter")
    c.add_argument("--request-timeout", type=float, metavar="S", help="clock seconds per request (mmexec run)")
    c.add_argument("--trial-timeout", type=float, metavar="S", help="wall seconds per trial before it is killed")
    c.add_argument("--compare", action="append", type=Path, default=[], metavar="DIR",
                   help="another campaign directory to compare against in the report (repeatable)")


def _fixed_requests(args: argparse.Namespace) -> tuple[dict[str, Any], ...]:
    problems: list[Problem] = []
    out: list[dict[str, Any]] = []
    for i, group in enumerate(args.request, start=1):
        fields: dict[str, Any] = {}
        for tok in group:
            key, sep, value = tok.partition("=")
            if not sep or not key.strip():
                problems.append(Problem(ArgMark("--request", i, 1), f"request: expected KEY=VALUE, got {tok!r}"))
                continue
            fields[key.strip()] = value
        out.append(fields)
    if args.requests is not None:
        data = load_yaml(args.requests)
        if not isinstance(data, YList) or not all(isinstance(x, YDict) for x in data):
            problems.append(Problem(getattr(data, "mark", Mark(str(args.requests), 1, 1)),
                                    "expected a YAML list of request mappings, e.g. '- {item: 3}'"))
        else:
            out += [_plain(x) for x in data]
    if problems:
        raise InputError(problems)
    return tuple(out)


def cmd_campaign(args: argparse.Namespace, *, out: TextIO | None = None,
                 progress: bool | None = None) -> int:
    """``mmexec campaign``: exit 0 when every trial succeeded, 1 otherwise; bad input
    raises InputError (exit 2)."""
    from mmexec.executive.config import load_config

    fixed = _fixed_requests(args)
    draws: dict[str, tuple[Any, ...]] = {}
    if args.draw:
        if fixed:
            raise InputError.at(ArgMark("--draw", 1, 1), "use either --draw or --request/--requests, not both")
        draws = _parse_draws(args.draw, _plain(load_config(args.config).raw))
    if args.requests_per_trial < 1:
        raise InputError.at(ArgMark("--requests-per-trial", 0, 0), "expected at least 1")
    params: dict[str, str] = {}
    for i, tok in enumerate(args.param, start=1):
        key, sep, value = tok.partition("=")
        if not sep or not key.strip():
            raise InputError.at(ArgMark("--param", i, 1), f"param: expected KEY=VALUE, got {tok!r}")
        params[key.strip()] = value
    opts = CampaignOptions(
        mission=args.mission, config=args.config, trials=args.trials, out=args.out, seed=args.seed,
        workers=args.workers, ray=args.ray, faults=args.faults, recovery=not args.no_recovery,
        randomize=not args.no_randomize,
        requests=RequestPlan(fixed=fixed, draws=draws, per_trial=args.requests_per_trial),
        params=params, request_timeout=args.request_timeout, trial_timeout=args.trial_timeout,
        compare=list(args.compare), progress=progress,
    )
    if opts.ray is not None:
        _import_ray(local=not opts.ray)
    _, results = run_campaign(opts, out=out)
    return 0 if results and all(r.outcome == "success" for r in results) else 1

