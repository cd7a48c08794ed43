"""Campaigns: many randomized trials of one mission, with success statistics.

``mmexec campaign MISSION --config CONFIG --trials N --out DIR`` (docs/campaigns.md)
runs trial ``i`` (0-based) as one ``mmexec run`` process::

    mmexec run MISSION --config DIR/config.yaml --seed SEED_i [--request K=V ...]
               [--param K=V ...] [--request-timeout S] [--no-recovery] --log DIR/trials/NNNN.jsonl

so every trial is reproducible alone with the command recorded in ``DIR/trials.csv``
(the same line without ``--log``). One module per piece:

* :mod:`.seeds`: ``SEED_i`` = the first 4 bytes (big-endian) of
  ``sha256(b"mmexec-campaign:<S>:<i>")``: independent-looking 32-bit seeds, stable across
  Python and numpy versions, computable by hand.
* :mod:`.faults`: ``DIR/config.yaml`` is the config with a fault profile applied (the
  built-in :data:`BUILTIN_PROFILES`, with the patches each backend declares, or a profile
  file; JSON-merge-patch semantics, :func:`merge_patch`) and, for a backend that draws its
  world per trial (the sim), ``randomize: true`` so each trial draws its world from the
  world's randomisation ranges with its seed.
* :mod:`.requests`: fixed requests (``--request``/``--requests``, the same for every
  trial) or drawn ones (``--draw FIELD=V1,V2,...`` or ``FIELD=@markers``, the marker
  ids of the sim world's items): trial ``i`` draws with ``random.Random(SEED_i)``.
* :mod:`.trial` (what a trial is and what it did) and :mod:`.process` (one trial as a
  ``mmexec run`` subprocess): a trial that crashes (a segfault in pybullet, ``os._exit``
  in a skill, a SIGKILL) is one ``error`` row, its pybullet state dies with it, and the
  command in the CSV is exactly what ran.
* :mod:`.pools`: where the trial processes are started: local worker processes
  (:class:`concurrent.futures.ProcessPoolExecutor`, spawn context, ``--workers`` of
  them) or Ray tasks (``--ray [ADDRESS]``).
* :mod:`.progress`: the progress line; :mod:`.run`: preparing ``DIR`` (resume included)
  and running the trials; :mod:`.report`: ``summary.json``, ``trials.csv``,
  ``report.md`` and PNG plots; :mod:`.cli`: the ``mmexec campaign`` subcommand.

Wall times are measured with :func:`time.monotonic` (they describe the machine, not the
mission); mission times are clock seconds from the trials' event logs.
"""

from __future__ import annotations

from mmexec.executive.campaign.cli import add_campaign_parser, cmd_campaign
from mmexec.executive.campaign.faults import (
    BUILTIN_PROFILES,
    FaultProfile,
    apply_fault_profile,
    builtin_profile,
    load_fault_profile,
    merge_patch,
)
from mmexec.executive.campaign.process import run_trial
from mmexec.executive.campaign.requests import RequestPlan
from mmexec.executive.campaign.run import Campaign, CampaignOptions, run_campaign
from mmexec.executive.campaign.seeds import trial_seed
from mmexec.executive.campaign.trial import TrialResult, TrialSpec, parse_trial_log

__all__ = [
    "BUILTIN_PROFILES",
    "Campaign",
    "CampaignOptions",
    "FaultProfile",
    "RequestPlan",
    "TrialResult",
    "TrialSpec",
    "add_campaign_parser",
    "apply_fault_profile",
    "builtin_profile",
    "cmd_campaign",
    "load_fault_profile",
    "merge_patch",
    "parse_trial_log",
    "run_campaign",
    "run_trial",
    "trial_seed",
]
