"""The ``mmexec campaign`` subcommand: its arguments (:func:`add_campaign_parser`) and
the command (:func:`cmd_campaign`), which turns them into
:class:`~mmexec.executive.campaign.run.CampaignOptions` and runs the campaign."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any, TextIO

from mmexec.config.yamlload import InputError, Mark, Problem, YDict, YList, load_yaml
from mmexec.executive.campaign.faults import BUILTIN_PROFILES
from mmexec.executive.campaign.jsondata import plain
from mmexec.executive.campaign.pools import import_ray, quiet_import_pybullet
from mmexec.executive.campaign.requests import RequestPlan, parse_draws
from mmexec.executive.campaign.run import CampaignOptions, run_campaign
from mmexec.executive.runner import ArgMark

__all__ = ["add_campaign_parser", "cmd_campaign"]


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
                   help=f"fault profile: {', '.join(BUILTIN_PROFILES)} or a profile .yaml file (default config)")
    c.add_argument("--no-recovery", action="store_true", help="disable every recovery node (ablation)")
    c.add_argument("--no-randomize", action="store_true", help="sim: keep the world's nominal poses")
    c.add_argument("--request", action="append", nargs="+", default=[], metavar="K=V",
                   help="a fixed request served by every trial (repeat for more)")
    c.add_argument("--requests", type=Path, metavar="FILE", help="YAML list of fixed requests")
    c.add_argument("--draw", action="append", default=[], metavar="FIELD=V1,V2|@markers|@objects",
                   help="draw a request field per trial from these values (@markers: the sim world's items' "
                        "marker ids; @objects: its untagged objects' names); commas inside brackets stay in "
                        "a value, so a list field draws whole lists: buttons=[b1,b2],[b3]")
    c.add_argument("--requests-per-trial", type=int, default=1, metavar="R", help="drawn requests per trial")
    c.add_argument("--param", action="append", default=[], metavar="K=V", help="override a mission parameter")
    c.add_argument("--request-timeout", type=float, metavar="S", help="clock seconds per request (mmexec run)")
    c.add_argument("--trial-timeout", type=float, metavar="S", help="wall seconds per trial before it is killed")
    c.add_argument("--answers", type=Path, metavar="FILE",
                   help="answers to ask_operator prompts for every trial (mmexec run --answers)")
    c.add_argument("--mcap", action="store_true",
                   help="also record each trial as DIR/trials/NNNN.mcap (Foxglove; docs/foxglove.md)")
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
            out += [plain(x) for x in data]
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
        quiet_import_pybullet()  # loading a sim config imports its backend, which imports pybullet
        draws = parse_draws(args.draw, plain(load_config(args.config).raw))
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
        compare=list(args.compare), progress=progress, mcap=args.mcap,
        answers=args.answers.resolve() if args.answers is not None else None,
    )
    if opts.ray is not None:
        import_ray(local=not opts.ray)
    _, results = run_campaign(opts, out=out)
    return 0 if results and all(r.outcome == "success" for r in results) else 1
