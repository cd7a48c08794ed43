"""Tick overhead of compiled missions versus the same tree built directly with py_trees.

Builds a generated mission of about 1000 nodes (a parallel of reactive sequences of
fallback / decorator blocks over trivial skill leaves; every group ends in a leaf that
stays RUNNING, so each tick traverses the whole tree), compiles it with
:func:`mmexec.executive.compiler.load_mission` (YAML written to a temporary file), and
builds the same shape from plain py_trees composites, decorators and behaviours whose
leaves run the same trivial generator functions. Both are ticked in this process,
interleaved in rounds; the script prints median per-tick times, the compile time
(load + validate + instantiate, median of ``--compiles`` runs, with its YAML-loading,
validation and instantiation parts measured in the same runs) and, as its last line,
``tick_overhead_ratio: X`` (compiled / raw median per tick).

Usage: ``python benchmarks/tick_overhead.py [--groups 21] [--ticks 300] [--compiles 15]``.
"""

from __future__ import annotations

import argparse
import gc
import statistics
import tempfile
import time
from collections.abc import Generator
from pathlib import Path
from typing import Any

import py_trees
from py_trees.common import Status

from mmexec.config.yamlload import load_yaml
from mmexec.drivers.interfaces import ManualClock, Robot
from mmexec.executive.compiler import load_mission
from mmexec.executive.context import ExecContext
from mmexec.skills.base import SkillContext, SkillRegistry, SkillSpec

BLOCKS = 9  # fallback blocks per group (5 nodes each)


def bench_ok(ctx: SkillContext) -> Generator[None, None, dict[str, Any]]:
    """Succeeds at once."""
    return {}
    yield  # makes this a generator


def bench_run(ctx: SkillContext) -> Generator[None, None, dict[str, Any]]:
    """Runs forever."""
    while True:
        yield


class _Bot(Robot):
    def __init__(self) -> None:
        self.clock = ManualClock()
        self.profile = {}

    def spin(self, period: float) -> None:
        self.clock.advance(period)


def mission_yaml(groups: int) -> str:
    lines = ["mission: bench", "tree:", "  parallel:"]
    for g in range(groups):
        lines += ["    - sequence:"]
        for b in range(BLOCKS):
            lines += [
                "        - fallback:",
                "            - invert: {skill: bench_ok}",
                "            - force_success: {skill: bench_ok}",
            ]
        lines += [
            "        - retry: {skill: bench_run}",
            "          attempts: 2",
            "      reactive: true",
            f"      name: g{g}",
        ]
    lines += ["  policy: all"]
    return "\n".join(lines) + "\n"


class GenLeaf(py_trees.behaviour.Behaviour):
    """Plain py_trees leaf doing the same work as a skill leaf: a generator per run."""

    def __init__(self, name: str, fn: Any, ctx: SkillContext) -> None:
        super().__init__(name)
        self.fn = fn
        self.ctx = ctx
        self.gen: Any = None

    def initialise(self) -> None:
        self.gen = self.fn(self.ctx)

    def update(self) -> Status:
        try:
            next(self.gen)
        except StopIteration:
            return Status.SUCCESS
        return Status.RUNNING


def raw_tree(groups: int, ctx: SkillContext) -> py_trees.behaviour.Behaviour:
    d = py_trees.decorators
    kids = []
    for g in range(groups):
        seq_kids: list[py_trees.behaviour.Behaviour] = []
        for _ in range(BLOCKS):
            seq_kids.append(py_trees.composites.Selector("fallback", memory=False, children=[
                d.Inverter("invert", GenLeaf("bench_ok", bench_ok, ctx)),
                d.FailureIsSuccess("force_success", GenLeaf("bench_ok", bench_ok, ctx)),
            ]))
        seq_kids.append(d.Retry("retry", GenLeaf("bench_run", bench_run, ctx), num_failures=2))
        kids.append(py_trees.composites.Sequence(f"g{g}", memory=False, children=seq_kids))
    return py_trees.composites.Parallel(
        "bench", policy=py_trees.common.ParallelPolicy.SuccessOnAll(synchronise=False), children=kids
    )


def count(node: py_trees.behaviour.Behaviour) -> int:
    return 1 + sum(count(c) for c in node.children)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--groups", type=int, default=21, help="parallel branches (48 nodes each)")
    ap.add_argument("--ticks", type=int, default=300, help="ticks per tree per round")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--compiles", type=int, default=15, help="compile runs (median reported)")
    args = ap.parse_args()

    reg = SkillRegistry()
    reg.register(SkillSpec("bench_ok", bench_ok))
    reg.register(SkillSpec("bench_run", bench_run))
    robot = _Bot()
    ctx = ExecContext(robot=robot, clock=robot.clock, registry=reg)
    sctx = SkillContext(robot=robot, clock=robot.clock)

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bench.yaml"
        path.write_text(mission_yaml(args.groups))
        # each run: YAML alone, then the full compile (load_mission reads the YAML
        # again, then validates; instantiate builds the tree); gc settled before each
        compile_times: list[float] = []
        yaml_only: list[float] = []
        validate_only: list[float] = []
        inst_only: list[float] = []
        for _ in range(args.compiles):
            gc.collect()
            t0 = time.perf_counter()
            load_yaml(path)
            t1 = time.perf_counter()
            mission = load_mission(path, reg)
            t2 = time.perf_counter()
            tree = mission.instantiate(ctx, {})
            t3 = time.perf_counter()
            yaml_only.append(t1 - t0)
            validate_only.append(max(0.0, (t2 - t1) - (t1 - t0)))
            inst_only.append(t3 - t2)
            compile_times.append(t3 - t1)
    raw = raw_tree(args.groups, sctx)
    n_compiled, n_raw = len(tree.nodes()), count(raw)
    assert n_compiled == n_raw, (n_compiled, n_raw)

    def per_tick(fn: Any, n: int) -> list[float]:
        out = []
        for _ in range(n):
            t0 = time.perf_counter()
            fn()
            out.append(time.perf_counter() - t0)
        return out

    # warm up, then check both trees are RUNNING (the whole tree is traversed every tick)
    for _ in range(20):
        assert tree.tick() is Status.RUNNING
        raw.tick_once()
    assert raw.status is Status.RUNNING
    compiled_s: list[float] = []
    raw_s: list[float] = []
    for _ in range(args.rounds):
        compiled_s += per_tick(tree.tick, args.ticks)
        raw_s += per_tick(raw.tick_once, args.ticks)
    c_med, r_med = statistics.median(compiled_s), statistics.median(raw_s)
    print(f"nodes: {n_compiled} (compiled) / {n_raw} (raw py_trees), ticks per tree: {len(compiled_s)}")
    med = statistics.median
    print(f"compile (load + validate + instantiate), median of {args.compiles}: {med(compile_times) * 1e3:.1f} ms "
          f"(min {min(compile_times) * 1e3:.1f}, max {max(compile_times) * 1e3:.1f}; target <= 50 ms)")
    print(f"  parts, medians of the same runs: YAML loading (config/yamlload.load_yaml) {med(yaml_only) * 1e3:.1f} ms, "
          f"executive validate {med(validate_only) * 1e3:.1f} ms, instantiate {med(inst_only) * 1e3:.1f} ms")
    print(f"compiled tree: median {c_med * 1e3:.3f} ms per tick ({c_med / n_compiled * 1e6:.2f} us per node)")
    print(f"raw py_trees:  median {r_med * 1e3:.3f} ms per tick ({r_med / n_raw * 1e6:.2f} us per node)")
    print(f"tick_overhead_ratio: {c_med / r_med:.3f}")


if __name__ == "__main__":
    main()
