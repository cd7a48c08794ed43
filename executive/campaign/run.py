"""One campaign: check its inputs, prepare ``DIR`` (``config.yaml``, ``campaign.json``,
resuming a campaign already there), run the trials not finished yet, then write the
outputs (:func:`run_campaign`)."""

from __future__ import annotations

import json
import logging
import math
import os
import sys
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

from mmexec.config.yamlload import InputError
from mmexec.executive.campaign.faults import apply_fault_profile, load_fault_profile
from mmexec.executive.campaign.jsondata import plain, write_json
from mmexec.executive.campaign.pools import quiet_import_pybullet, run_local, run_ray
from mmexec.executive.campaign.progress import CampaignProgress
from mmexec.executive.campaign.report import write_outputs
from mmexec.executive.campaign.requests import RequestPlan, cli_value
from mmexec.executive.campaign.seeds import trial_seed
from mmexec.executive.campaign.trial import TrialResult, TrialSpec, parse_trial_log
from mmexec.executive.runner import SEED_RANGE, ArgMark
from mmexec.executive.values import MAX_SECONDS

if TYPE_CHECKING:
    from mmexec.executive.config import LoadedConfig

__all__ = ["Campaign", "CampaignOptions", "run_campaign"]

log = logging.getLogger(__name__)


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
    #: record each trial as DIR/trials/NNNN.mcap too (``mmexec run --mcap``)
    mcap: bool = False
    #: answers to the trials' operator prompts (``mmexec run --answers``; an absolute path)
    answers: Path | None = None


#: Settings that must match for a DIR to be resumed (the identity of its trials).
_IDENTITY_KEYS = ("mission", "mission_sha256", "config", "config_sha256", "seed", "faults", "faults_patches",
                  "recovery", "randomize", "requests", "params", "request_timeout")


#: Where a campaign has each trial's ground truth written (relative to DIR/config.yaml).
TRUTH_SIDECAR = "truth/{seed}.jsonl"


def _anchor_folders(cfg: dict[str, Any], loaded: LoadedConfig) -> dict[str, Any]:
    """``cfg`` with the folders the user's config names relative to itself (``roots:``,
    ``skills.paths``) written absolute, since ``DIR/config.yaml`` lies elsewhere. Each
    ``skills.paths`` folder is listed under ``roots:`` too, so the generated config
    passes the rule that skill folders lie inside the config's folder tree or a root."""
    roots = [str(r) for r in loaded.roots]
    paths = [str(p) for p in loaded.skill_paths]
    if paths:
        cfg["skills"] = {**cfg.get("skills", {}), "paths": paths}
    if roots or paths:
        cfg["roots"] = list(dict.fromkeys(roots + paths))
    return cfg


#: where a trial's ground truth goes (relative to DIR/config.yaml), for a backend that writes one
TRUTH_FILE = "truth/{seed}.jsonl"


def _ask_for_truth(cfg: dict[str, Any], truth_key: str | None) -> None:
    """Have each trial write its ground truth to DIR/:data:`TRUTH_FILE` (the backend's
    ``truth_key``), unless the config names a file already, so the campaign can count
    what really happened (:func:`~mmexec.executive.campaign.trial.read_truth`)."""
    section = cfg.get(str(cfg.get("backend", "")))
    if truth_key is not None and isinstance(section, dict) and section.get(truth_key) is None:
        section[truth_key] = TRUTH_FILE


def _dump_config(cfg: Mapping[str, Any], path: Path, header: str) -> None:
    import yaml  # writing only; all reading goes through mmexec.config.yamlload

    text = yaml.safe_dump(plain(cfg), sort_keys=False, default_flow_style=None)
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
        from mmexec.executive.config import load_config, load_skill_modules
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
        quiet_import_pybullet()  # the sim backend and the built-in arm skills import it
        loaded = load_config(o.config)
        load_skill_modules(loaded)  # a user module's problem is located in the user's config, not DIR/config.yaml
        profile = load_fault_profile(o.faults)
        cfg = _anchor_folders(apply_fault_profile(loaded.raw, profile, randomize=o.randomize), loaded)
        _ask_for_truth(cfg, loaded.spec.truth_key)
        randomizes = loaded.spec.randomize_key is not None  # the backend draws its world per trial
        truth_key = loaded.spec.truth_key  # each trial's ground truth in DIR/truth/SEED.jsonl, unless the config says
        backend_section = cfg.setdefault(str(cfg.get("backend")), {}) if truth_key is not None else None
        if isinstance(backend_section, dict) and backend_section.get(truth_key) is None:
            backend_section[truth_key] = TRUTH_SIDECAR
        try:
            self.dir.mkdir(parents=True, exist_ok=True)
            self.trials_dir.mkdir(exist_ok=True)
        except OSError as e:
            raise InputError.at(ArgMark("--out", 0, 0), f"{self.dir}: cannot create: {e.strerror or e}") from None
        header = (f"# Generated by mmexec campaign from {o.config} (sha256 {loaded.sha256[:12]}) with fault profile "
                  f"{profile.name!r} ({profile.source})" + (", randomize on" if randomizes and o.randomize else "")
                  + ".\n")
        staged = self.dir / "config.yaml.new"
        _dump_config(cfg, staged, header)
        plan = o.requests
        # Preflight with the runner itself: config (as trials will see it), skill modules,
        # mission, every trial's requests; nothing is connected.
        seeds = [trial_seed(o.seed, i) for i in range(o.trials)]
        per_trial = [plan.requests_for(s) for s in seeds]
        # each distinct request once, located at the option it came from
        distinct: dict[str, Request] = {}
        for i, reqs in enumerate(per_trial):
            for j, r in enumerate(reqs):
                key = json.dumps({k: cli_value(v) for k, v in r.items()}, sort_keys=True)
                if key not in distinct and (r or not plan.draws):
                    where = (ArgMark(f"--draw (trial {i:04d})", 0, 0) if plan.draws
                             else ArgMark("--request/--requests", j + 1, 1) if plan.fixed
                             else ArgMark("mmexec campaign (no --request or --draw given)", 0, 0))
                    distinct[key] = Request({k: cli_value(v) for k, v in r.items()}, where)
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
            "faults_patches": plain(profile.patches.get(str(cfg.get("backend")), ())),
            "faults_description": profile.description,
            "recovery": o.recovery,
            "randomize": o.randomize if randomizes else None,
            "requests": {"fixed": plain(plan.fixed), "draws": plain(plan.draws), "per_trial": plan.per_trial},
            "requests_description": plan.describe(),
            "params": dict(o.params),
            "request_timeout": o.request_timeout,
            "backend": cfg.get("backend"),
        }
        self._check_resume(identity)
        os.replace(staged, self.config_path)
        identity["trials"] = max(o.trials, int(self.identity.get("trials", 0) or 0))
        self.identity = identity
        write_json(self.dir / "campaign.json", identity)
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
                 if plain(old.get(k)) != plain(identity.get(k))]
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
                argv += ["--request", *(f"{k}={cli_value(v)}" for k, v in r.items())]
        for k, v in o.params.items():
            argv += ["--param", f"{k}={v}"]
        if o.request_timeout is not None:
            argv += ["--request-timeout", f"{o.request_timeout:g}"]
        if not o.recovery:
            argv.append("--no-recovery")
        if o.answers is not None:
            argv += ["--answers", str(o.answers)]
        log_path = self.trials_dir / f"{index:04d}.jsonl"
        # --overwrite: a resumed campaign runs an interrupted trial again into its own log
        argv += ["--log", str(log_path)]
        if o.mcap:
            argv += ["--mcap", str(self.trials_dir / f"{index:04d}.mcap")]
        argv.append("--overwrite")
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
        write_json(self.trials_dir / f"{result.index:04d}.json", result.to_json())

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
        progress = CampaignProgress(self.out, total=len(self.specs), done=list(done.values()),
                                     enabled=o.progress)
        if pending:
            runner = run_ray if o.ray is not None else run_local
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


def run_campaign(options: CampaignOptions, *, out: TextIO | None = None) -> tuple[Campaign, list[TrialResult]]:
    """Prepare and run a campaign, then write summary.json, trials.csv, report.md and the
    plots. Returns the campaign and its results (trial order)."""
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
