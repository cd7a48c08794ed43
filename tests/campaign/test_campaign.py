"""Campaign tests: seeds, fault profiles, statistics, local and Ray runs, crashes, resume.

The mock missions here run in about a second per trial (mostly interpreter start-up:
every trial is its own ``mmexec run`` process). ``coin.yaml`` succeeds on even items,
fails on odd ones and SIGKILLs its own process on item 9, so each trial's expected
outcome follows from the item its seed draws.
"""

from __future__ import annotations

import csv
import hashlib
import json
import os
import random
import shlex
from collections.abc import Iterator
from pathlib import Path

import pytest

from mmexec.config.yamlload import InputError, load_yaml
from mmexec.executive.campaign import (
    CampaignOptions,
    RequestPlan,
    TrialResult,
    apply_fault_profile,
    builtin_profile,
    load_fault_profile,
    merge_patch,
    run_campaign,
    trial_seed,
)
from mmexec.executive.campaign.report import summarize, wilson_interval

HERE = Path(__file__).resolve().parent
COIN = HERE / "coin.yaml"
COIN_CFG = HERE / "coin_mock.yaml"
SIM_ARM = HERE / "sim_arm.yaml"
SIM_CFG = HERE / "sim_small.yaml"
ITEMS = ("2", "3", "9")
COIN_SEED = 5
COIN_TRIALS = 6


def expected_outcome(item: int) -> str:
    return "error" if item == 9 else ("failure" if item % 2 else "success")


def coin_items(seed: int, n: int) -> list[int]:
    return [int(RequestPlan(draws={"item": ITEMS}).requests_for(trial_seed(seed, i))[0]["item"]) for i in range(n)]


@pytest.fixture(scope="module")
def skills_on_path() -> Iterator[None]:
    """Trial processes import ``campaign_test_skills`` from this folder through
    coin_mock.yaml's ``skills.paths`` alone: no PYTHONPATH."""
    with pytest.MonkeyPatch.context() as mp:
        mp.delenv("PYTHONPATH", raising=False)
        yield


def coin_options(out: Path, **kw: object) -> CampaignOptions:
    base: dict[str, object] = {"mission": COIN, "config": COIN_CFG, "trials": COIN_TRIALS, "out": out, "seed": COIN_SEED,
                                   "workers": 2, "requests": RequestPlan(draws={"item": ITEMS}), "progress": False}
    base.update(kw)
    return CampaignOptions(**base)  # type: ignore[arg-type]


@pytest.fixture(scope="module")
def local_run(tmp_path_factory: pytest.TempPathFactory, skills_on_path: None) -> tuple[Path, list[TrialResult]]:
    out = tmp_path_factory.mktemp("local")
    with open(os.devnull, "w") as null:
        _, results = run_campaign(coin_options(out), out=null)
    return out, results


# --------------------------------------------------------------------------- pure parts


def test_trial_seed_is_the_documented_formula() -> None:
    for s, i in ((0, 0), (7, 199), (123456789, 3)):
        digest = hashlib.sha256(f"mmexec-campaign:{s}:{i}".encode()).digest()
        assert trial_seed(s, i) == int.from_bytes(digest[:4], "big")
    assert trial_seed(0, 0) == 3356100361
    assert len({trial_seed(1, i) for i in range(1000)}) == 1000
    assert trial_seed(1, 0) != trial_seed(0, 1)


def test_request_draws_use_random_with_the_trial_seed() -> None:
    plan = RequestPlan(draws={"item": (1, 2, 3, 4, 5, 6), "place": ("a", "b")}, per_trial=2)
    reqs = plan.requests_for(42)
    rng = random.Random(42)
    assert reqs == [{"item": rng.choice((1, 2, 3, 4, 5, 6)), "place": rng.choice(("a", "b"))} for _ in range(2)]
    assert RequestPlan(fixed=({"item": 3},)).requests_for(1) == [{"item": 3}]
    assert RequestPlan().requests_for(1) == [{}]


@pytest.mark.parametrize(("k", "n", "lo", "hi"), [
    (8, 10, 0.4902, 0.9433),     # hand-computed with z = 1.96 (see the module doc formula)
    (0, 10, 0.0, 0.2775),
    (10, 10, 0.7225, 1.0),
    (196, 200, 0.9497, 0.9922),
    (1, 2, 0.0945, 0.9055),
])
def test_wilson_interval_matches_hand_computed_values(k: int, n: int, lo: float, hi: float) -> None:
    a, b = wilson_interval(k, n)
    assert a == pytest.approx(lo, abs=5e-4) and b == pytest.approx(hi, abs=5e-4)


def test_wilson_interval_edges() -> None:
    assert wilson_interval(0, 0) == (0.0, 1.0)
    assert wilson_interval(0, 3)[0] == 0.0 and wilson_interval(3, 3)[1] == 1.0
    with pytest.raises(ValueError):
        wilson_interval(4, 3)


def test_merge_patch_semantics() -> None:
    target = {"a": 1, "b": {"c": 2, "d": 3}, "e": [1, 2]}
    assert merge_patch(target, {"b": {"c": None, "x": 9}, "e": [3], "f": {"g": 1}}) == \
        {"a": 1, "b": {"d": 3, "x": 9}, "e": [3], "f": {"g": 1}}
    assert target == {"a": 1, "b": {"c": 2, "d": 3}, "e": [1, 2]}
    assert merge_patch(target, {"b": None}) == {"a": 1, "e": [1, 2]}


def test_fault_profiles_overlay_the_backend_section() -> None:
    cfg = {"backend": "sim", "sim": {"world": "lab", "faults": {"marker_bias": {"box_2": [0.02, 0.0]}}}}
    nominal = apply_fault_profile(cfg, builtin_profile("nominal"), randomize=True)
    assert nominal["sim"] == {"world": "lab", "randomize": True}
    first = apply_fault_profile(cfg, builtin_profile("arm_fail_first"), randomize=False)
    assert first["sim"] == {"world": "lab", "faults": {"arm_fail_attempts": [1]}, "randomize": False}
    second = apply_fault_profile(cfg, builtin_profile("arm_fail_second"), randomize=True)
    assert second["sim"]["faults"] == {"arm_fail_attempts": [2]}
    as_is = apply_fault_profile(cfg, builtin_profile("config"), randomize=True)
    assert as_is["sim"]["faults"] == {"marker_bias": {"box_2": [0.02, 0.0]}}
    mock = {"backend": "mock", "mock": {"gripper": {"grasps": [False], "object_width": 0.03}}}
    assert apply_fault_profile(mock, builtin_profile("nominal"), randomize=True)["mock"] == \
        {"gripper": {"object_width": 0.03}, "arm": {}, "base": {}, "camera": {}}  # RFC 7396 keeps empty objects
    assert apply_fault_profile(mock, builtin_profile("arm_fail_first"), randomize=True)["mock"]["gripper"] == \
        {"object_width": 0.03, "grasps": [False]}
    with pytest.raises(InputError, match=r"^--faults: fault profile 'sensor_dropout' has no patch for backend 'mock'"):
        apply_fault_profile(mock, builtin_profile("sensor_dropout"), randomize=True)


def test_fault_profile_files_and_errors(tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r"^--faults: unknown fault profile 'arm_fial_first'"):
        load_fault_profile("arm_fial_first")
    p = tmp_path / "blocked.yaml"
    p.write_text("description: box 3 walled off\nsim:\n  faults: {nav_blocked: [box_3]}\n")
    prof = load_fault_profile(str(p))
    cfg = apply_fault_profile({"backend": "sim", "sim": {"faults": {"arm_fail": "always"}}}, prof, randomize=True)
    assert cfg["sim"]["faults"] == {"nav_blocked": ["box_3"]} and prof.name == "blocked"
    bad = tmp_path / "bad.yaml"
    bad.write_text("sim: [1]\nbase: both\n")
    with pytest.raises(InputError) as ei:
        load_fault_profile(str(bad))
    lines = str(ei.value).splitlines()
    assert lines[0].startswith(f"{bad}:1:6: sim: expected a mapping")
    assert lines[1].startswith(f"{bad}:2:7: base: expected 'nominal' or 'config'")


def test_summarize_counts_rates_times_and_reasons() -> None:
    def tr(i: int, outcome: str, clock: float, rec: int, reason: str = "", node: str = "") -> TrialResult:
        reqs = [] if outcome == "error" else [{"request": {"item": i}, "outcome": outcome, "duration": clock,
                                               "recoveries": rec, "reason": reason}]
        return TrialResult(i, i, outcome, clock, 2.0 + i, rec, reason, "execution" if node else "", node,
                           requests=reqs)

    results = [tr(0, "success", 10.0, 0), tr(1, "success", 20.0, 1), tr(2, "failure", 5.0, 2, "no path", "m/nav"),
               tr(3, "failure", 7.0, 2, "no path", "m/nav"), tr(4, "error", 0.0, 0, "killed by SIGKILL")]
    s = summarize(results)
    assert (s["trials"], s["successes"], s["failures"], s["errors"]) == (5, 2, 2, 1)
    assert s["success_rate"] == pytest.approx(0.4)
    assert s["success_rate_ci95"] == pytest.approx(list(wilson_interval(2, 5)))
    assert s["clock_per_request"]["mean"] == pytest.approx(10.5) and s["clock_per_request"]["median"] == 8.5
    assert s["clock_per_success"]["mean"] == pytest.approx(15.0)
    assert s["wall_per_trial"]["median"] == pytest.approx(4.0)
    assert s["failure_reasons"] == {"no path": 2, "killed by SIGKILL": 1}
    assert s["failure_causes"] == {"execution @ nav": 2, "error (crashed trial)": 1}
    assert s["recoveries"] == {"0": 2, "1": 1, "2": 2}
    assert [e["trial"] for e in s["errored_trials"]] == [4]


# --------------------------------------------------------------------------- local runs


def test_local_campaign_outcomes_follow_each_trials_draw(local_run: tuple[Path, list[TrialResult]]) -> None:
    out, results = local_run
    items = coin_items(COIN_SEED, COIN_TRIALS)
    assert {expected_outcome(i) for i in items} == {"success", "failure", "error"}, "seed must cover all cases"
    assert [r.index for r in results] == list(range(COIN_TRIALS))
    for r, item in zip(results, items):
        assert r.seed == trial_seed(COIN_SEED, r.index)
        assert r.outcome == expected_outcome(item), (r.index, item, r.reason)
        if r.outcome == "success":
            assert r.clock == pytest.approx(0.5 * item, abs=0.2) and r.reason == ""
        elif r.outcome == "failure":
            assert r.reason == f"ct_coin: item {item} is odd" or r.reason.endswith(f"item {item} is odd")
            assert r.failure_kind == "postcondition" and r.failure_node == "coin/coin"
        assert f"--request item={item}" in r.command and f"--seed {r.seed}" in r.command
        assert (out / "trials" / f"{r.index:04d}.jsonl").is_file()


def test_crashed_trial_is_an_error_and_the_campaign_completes(local_run: tuple[Path, list[TrialResult]]) -> None:
    out, results = local_run
    crashed = [r for r in results if r.outcome == "error"]
    assert crashed and all(r.reason.startswith("trial process killed by SIGKILL") for r in crashed)
    assert all(r.exit_code == -9 for r in crashed)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["errors"] == len(crashed) and summary["trials"] == COIN_TRIALS
    assert {e["trial"] for e in summary["errored_trials"]} == {r.index for r in crashed}


def test_summary_csv_and_report_contents(local_run: tuple[Path, list[TrialResult]]) -> None:
    out, results = local_run
    items = coin_items(COIN_SEED, COIN_TRIALS)
    ok = sum(expected_outcome(i) == "success" for i in items)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["successes"] == ok and summary["success_rate"] == pytest.approx(ok / COIN_TRIALS)
    assert summary["success_rate_ci95"] == pytest.approx(list(wilson_interval(ok, COIN_TRIALS)))
    odd = [i for i in items if expected_outcome(i) == "failure"]
    assert summary["failure_reasons"][f"item {odd[0]} is odd"] == odd.count(odd[0])
    assert summary["campaign"]["faults"] == "config" and summary["campaign"]["recovery"] is True
    served = [i for i in items if i != 9]
    assert summary["clock_per_request"]["n"] == len(served)
    assert summary["clock_per_request"]["mean"] == pytest.approx(sum(0.5 * i for i in served) / len(served), abs=0.2)
    with (out / "trials.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert [int(r["trial"]) for r in rows] == list(range(COIN_TRIALS))
    for row, item in zip(rows, items):
        assert row["outcome"] == expected_outcome(item)
        assert int(row["seed"]) == trial_seed(COIN_SEED, int(row["trial"]))
        assert row["command"].startswith(f"mmexec run {COIN} --config {out / 'config.yaml'} --seed {row['seed']}")
    report = (out / "report.md").read_text()
    assert f"({ok}/{COIN_TRIALS})" in report and "95% Wilson CI" in report
    for r in results:
        if r.outcome != "success":
            assert f"`{r.command}`" in report
    for png in ("mission_time.png", "failure_causes.png"):
        assert (out / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_recorded_command_reproduces_a_failed_trial(local_run: tuple[Path, list[TrialResult]], tmp_path: Path,
                                                    skills_on_path: None) -> None:
    from mmexec.executive.cli import main
    from mmexec.executive.eventlog import read_log

    _, results = local_run
    failed = next(r for r in results if r.outcome == "failure")
    argv = shlex.split(failed.command)
    assert argv[0] == "mmexec"
    log = tmp_path / "again.jsonl"
    assert main(argv[1:] + ["--log", str(log)]) == 1
    end = next(r for r in read_log(log) if r["event"] == "request_end")
    assert (end["outcome"], end["reason"], end["duration"]) == ("failure", failed.reason, failed.clock)


def test_resume_skips_finished_trials(tmp_path: Path, skills_on_path: None) -> None:
    out = tmp_path / "c"
    opts = coin_options(out, trials=3, requests=RequestPlan(draws={"item": ("2", "4")}))
    with open(os.devnull, "w") as null:
        first, results = run_campaign(opts, out=null)
        assert first.ran == 3 and [r.outcome for r in results] == ["success"] * 3
        kept_log = (out / "trials" / "0000.jsonl").stat().st_mtime_ns
        (out / "trials" / "0001.json").unlink()          # row lost, log complete: recovered from the log
        (out / "trials" / "0002.json").unlink()          # row and log lost: runs again
        (out / "trials" / "0002.jsonl").unlink()
        again, results = run_campaign(coin_options(out, trials=4, requests=RequestPlan(draws={"item": ("2", "4")})),
                                      out=null)
    assert again.ran == 2 and [r.index for r in results] == [0, 1, 2, 3]
    assert (out / "trials" / "0000.jsonl").stat().st_mtime_ns == kept_log
    assert json.loads((out / "summary.json").read_text())["trials"] == 4
    assert json.loads((out / "campaign.json").read_text())["trials"] == 4
    with pytest.raises(InputError, match=r"^--out: .* holds a campaign with other settings \(seed: 5 there, 6 now"):
        run_campaign(coin_options(out, trials=4, seed=6, requests=RequestPlan(draws={"item": ("2", "4")})))


def test_cli_bad_input_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str], skills_on_path: None) -> None:
    from mmexec.executive.cli import main

    base = ["campaign", str(COIN), "--config", str(COIN_CFG), "--out", str(tmp_path / "x")]
    cases = [
        (["--trials", "0", "--draw", "item=2"], "--trials: expected at least 1 trial, got 0"),
        (["--trials", "2", "--draw", "item=2", "--faults", "nosuch"], "--faults: unknown fault profile 'nosuch'"),
        (["--trials", "2", "--draw", "item=@markers"], "--draw #1: @markers needs a sim config"),
        (["--trials", "2", "--draw", "itme=2"], "--draw (trial 0000): request 1: request: unknown field 'itme'"),
        (["--trials", "2"], "mmexec campaign (no --request or --draw given): request 1: request: missing field"),
        (["--trials", "2", "--request", "item=x"], "--request/--requests #1: request 1: request field 'item'"),
    ]
    for extra, message in cases:
        capsys.readouterr()
        assert main(base + extra) == 2, extra
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) >= 1 and message in err[0] and "Traceback" not in "\n".join(err), (extra, err)


# --------------------------------------------------------------------------- sim


def test_sim_campaign_fault_profile_and_recovery_ablation(tmp_path: Path) -> None:
    plan = RequestPlan(draws={"item": tuple(range(1, 7))})
    kw = {"mission": SIM_ARM, "config": SIM_CFG, "trials": 2, "seed": 3, "workers": 2, "faults": "arm_fail_first",
              "requests": plan, "progress": False}
    with open(os.devnull, "w") as null:
        _, with_rec = run_campaign(CampaignOptions(out=tmp_path / "rec", **kw), out=null)  # type: ignore[arg-type]
        _, without = run_campaign(CampaignOptions(out=tmp_path / "norec", recovery=False,  # type: ignore[arg-type]
                                                  compare=[tmp_path / "rec"], **kw), out=null)
    assert [(r.outcome, r.recoveries) for r in with_rec] == [("success", 1), ("success", 1)]
    assert [r.outcome for r in without] == ["failure", "failure"]
    assert all("injected fault, attempt 1" in r.reason and r.command.endswith("--no-recovery") for r in without)
    cfg = load_yaml(tmp_path / "rec" / "config.yaml")
    assert cfg["sim"]["faults"] == {"arm_fail_attempts": [1]} and cfg["sim"]["randomize"] is True
    markers = {int(r.requests[0]["request"]["item"]) for r in with_rec}
    assert markers <= set(range(1, 7))
    summary = json.loads((tmp_path / "norec" / "summary.json").read_text())
    assert [(c["recovery"], c["success_rate"]) for c in summary["compared_with"]] == [(True, 1.0)]
    report = (tmp_path / "norec" / "report.md").read_text()
    assert "| this campaign | arm_fail_first | off | 2 | 0.000 |" in report
    assert "| arm_fail_first | on | 2 | 1.000 |" in report
    assert (tmp_path / "norec" / "success_rate.png").is_file()


# --------------------------------------------------------------------------- Ray


def test_ray_campaign_matches_local_outcomes(local_run: tuple[Path, list[TrialResult]], tmp_path: Path) -> None:
    _out, local = local_run
    with open(os.devnull, "w") as null:
        _, remote = run_campaign(coin_options(tmp_path / "ray", ray=""), out=null)
    assert [(r.index, r.seed, r.outcome, r.reason, r.clock, r.recoveries) for r in remote] == \
        [(r.index, r.seed, r.outcome, r.reason, r.clock, r.recoveries) for r in local]


def test_trial_timeout_kills_a_hung_trial(tmp_path: Path, skills_on_path: None) -> None:
    opts = coin_options(tmp_path / "hang", trials=1, workers=1, trial_timeout=4.0,
                        requests=RequestPlan(fixed=({"item": "7"},)))
    with open(os.devnull, "w") as null:
        _, (r,) = run_campaign(opts, out=null)
    assert r.outcome == "error" and r.exit_code == -9
    assert r.reason.startswith("killed after 4 s of wall time (--trial-timeout)")
    assert 4.0 <= r.wall < 30.0


def test_progress_line_on_a_terminal_and_plain_lines_otherwise() -> None:
    import io

    from mmexec.executive.campaign.progress import CampaignProgress

    def result(i: int, outcome: str) -> TrialResult:
        return TrialResult(i, 10 + i, outcome, 1.5, 0.5, 0, "" if outcome == "success" else "boom")

    tty = io.StringIO()
    p = CampaignProgress(tty, total=4, done=[result(0, "success")], enabled=True)
    p.add(result(1, "failure"))
    assert tty.getvalue().startswith("\r[2/4] 1 ok (50.0%), elapsed ") and "ETA " in tty.getvalue()
    p.finish()
    assert tty.getvalue().endswith("\r\x1b[K")
    plain = io.StringIO()
    p = CampaignProgress(plain, total=2, done=[], enabled=False)
    p.add(result(0, "error"))
    line = plain.getvalue()
    assert line.startswith("trial 0000 seed 10: error, 1.5 s clock, 0.5 s wall: boom  [1/2] 0 ok (0.0%), 1 errors")
    assert "\r" not in line and line.endswith("\n")


def test_mcap_records_each_trial_and_stays_out_of_the_reproduce_command(tmp_path: Path,
                                                                        skills_on_path: None) -> None:
    # --mcap: every trial also writes DIR/trials/NNNN.mcap with the channels of `run --mcap`
    # (docs/foxglove.md); the recorded command to reproduce a trial names none of the
    # campaign's own output files
    from mcap.reader import make_reader

    out = tmp_path / "c"
    opts = coin_options(out, trials=2, requests=RequestPlan(draws={"item": ("2", "4")}), mcap=True)
    with open(os.devnull, "w") as null:
        _, results = run_campaign(opts, out=null)
    assert [r.outcome for r in results] == ["success", "success"]
    for r in results:
        path = out / "trials" / f"{r.index:04d}.mcap"
        with path.open("rb") as f:
            topics = {channel.topic for _schema, channel, _message in make_reader(f).iter_messages()}
        assert "/mmexec/events" in topics and "/mmexec/tree" in topics
        assert "--mcap" not in r.command and "--overwrite" not in r.command and "--log" not in r.command
