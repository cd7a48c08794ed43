"""Harness for the end-to-end fetch scenarios: run trees/fetch_item.yaml in-process on
the pybullet backend (one robot build per run, the executive's own Runner), with sim
faults patched into a copy of the config, a chosen start pose, and ground truth sampled
at the end of every request (SIM-ONLY, for the assertions)."""

from __future__ import annotations

import io
import json
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mmexec.drivers.interfaces import Pose2D
from mmexec.executive.config import LoadedConfig, build_robot
from mmexec.executive.eventlog import read_log
from mmexec.executive.runner import ArgMark, Progress, Request, RequestResult, Runner, RunOptions

REPO = Path(__file__).resolve().parents[2]
MISSION = REPO / "trees" / "fetch_item.yaml"
LOCOBOT_SIM = REPO / "config" / "locobot_sim.yaml"


def log_records(log: Path, drop: Sequence[str] = ()) -> list[dict[str, Any]]:
    """The records of the JSON-lines event log ``log``, in order, without the fields in
    ``drop`` (wall-clock times, pids, paths: what differs between equal runs)."""
    out = []
    for line in log.read_text().splitlines():
        rec = json.loads(line)
        for k in drop:
            rec.pop(k, None)
        out.append(rec)
    return out


@dataclass
class Truth:
    """Ground truth at one request's end."""

    in_depot: dict[str, str]
    held: str | None
    base: Pose2D
    faults_fired: list[tuple[float, str]]


@dataclass
class SimRun:
    """What a scenario produced: exit code, per-request results, the event log records,
    ground truth at each request end, and the runner's console output."""

    exit_code: int
    results: list[RequestResult]
    records: list[dict[str, Any]]
    truth: list[Truth]
    out: str
    log_path: Path
    extra: dict[str, Any] = field(default_factory=dict)

    def events(self, name: str, request: int | None = None) -> list[dict[str, Any]]:
        """Records of event ``name``, optionally only those of request ``request`` (1-based)."""
        out, current = [], 0
        for r in self.records:
            if r.get("event") == "request_start":
                current += 1
            if r.get("event") == name and (request is None or current == request):
                out.append(r)
        return out

    def recoveries(self, node_suffix: str, request: int | None = None) -> list[dict[str, Any]]:
        """``recovery_attempt`` records of the recovery node whose path ends with ``node_suffix``."""
        return [r for r in self.events("recovery_attempt", request) if str(r.get("node", "")).endswith(node_suffix)]


def sim_config(tmp_path: Path, *, faults: str | None = None, base: Path = LOCOBOT_SIM) -> Path:
    """A copy of ``base`` with ``faults`` (a YAML flow mapping) under ``sim:``."""
    text = base.read_text()
    if faults is not None:
        assert "\nsim:\n" in text
        text = text.replace("\nsim:\n", f"\nsim:\n  faults: {faults}\n", 1)
    path = tmp_path / base.name
    path.write_text(text)
    return path


def run_fetch(
    tmp_path: Path,
    items: Sequence[int],
    *,
    faults: str | None = None,
    start: Pose2D | None = None,
    params: Mapping[str, Any] | None = None,
    config: Path = LOCOBOT_SIM,
    seed: int = 0,
    setup: Callable[[Any, Runner], None] | None = None,
) -> SimRun:
    """Serve one ``item=K`` request per entry of ``items`` and collect everything."""
    cfg = sim_config(tmp_path, faults=faults, base=config)
    log_path = tmp_path / "events.jsonl"
    out = io.StringIO()
    truth: list[Truth] = []
    holder: dict[str, Any] = {}
    reqs = [Request({"item": str(k)}, ArgMark("--request", i, 1)) for i, k in enumerate(items, start=1)]
    opts = RunOptions(mission=MISSION, config=cfg, requests=reqs, params=dict(params or {}), seed=seed,
                      log_path=log_path)

    def factory(loaded: LoadedConfig) -> Any:
        robot = build_robot(loaded, seed=seed)
        if start is not None:
            robot.core.place_base(start)
            robot.base.reset_estimate(start)
        holder["robot"] = robot
        if setup is not None:
            setup(robot, runner)
        return robot

    runner = Runner(opts, out=out, err=out, progress=Progress(io.StringIO(), enabled=False), robot_factory=factory)

    def on_record(record: dict[str, Any]) -> None:
        if record.get("event") == "request_end":
            t = holder["robot"].truth
            truth.append(Truth(t.items_in_depot(), t.held_item(), t.base_pose(), t.faults_fired()))

    runner.add_log_listener(on_record)
    runner.prepare()
    code = runner.run()
    return SimRun(code, list(runner.results), read_log(log_path), truth, out.getvalue(), log_path)


def heading_error(a: float, b: float) -> float:
    """|a - b| wrapped to [0, pi] [rad]."""
    return abs(math.atan2(math.sin(a - b), math.cos(a - b)))
