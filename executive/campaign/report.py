"""Campaign statistics and outputs: summary.json, trials.csv, report.md, PNG plots.

:func:`wilson_interval` is the Wilson score interval for a binomial proportion
(Wilson 1927): for ``k`` successes in ``n`` trials and ``z`` the normal quantile
(1.959964 for 95 %),

    centre = (p + z^2 / 2n) / (1 + z^2 / n),
    half   = z * sqrt(p (1 - p) / n + z^2 / 4n^2) / (1 + z^2 / n),   p = k / n.

Unlike the normal approximation it stays inside [0, 1] and is not degenerate at 0 or n
successes, which matters for success rates near 1.

Definitions used in the summary (docs/campaigns.md):

* ``success_rate`` = successes / trials, where trials counts every recorded trial,
  errors (crashed trials) included: a crash is not a success.
* clock times are the mission's clock seconds from the event logs (sim time in sim);
  ``clock_per_request`` covers every served request, ``clock_per_success`` only the
  successful ones. ``wall_per_trial`` is the trial process's wall time [s], including
  interpreter and backend start-up.
* ``recoveries`` is a histogram of recoveries used per trial (summed over its requests).
"""

from __future__ import annotations

import csv
import json
import logging
import math
import statistics
from collections import Counter
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from mmexec.executive.campaign.fruittruth import fruit_report_lines, summarize_fruit
from mmexec.executive.campaign.navtruth import nav_report_lines, summarize_nav
from mmexec.executive.campaign.trial import TrialResult

__all__ = ["Z95", "summarize", "wilson_interval", "write_outputs"]

log = logging.getLogger(__name__)

#: Two-sided 95 % standard normal quantile.
Z95 = 1.959963984540054

_CSV_FIELDS = ("trial", "seed", "outcome", "requests", "clock_s", "wall_s", "recoveries", "failure_reason",
               "failure_kind", "failure_node", "exit_code", "command")


def wilson_interval(successes: int, trials: int, z: float = Z95) -> tuple[float, float]:
    """Wilson score interval (lower, upper) for ``successes`` out of ``trials``; (0, 1)
    when there are no trials."""
    if trials <= 0:
        return (0.0, 1.0)
    if not 0 <= successes <= trials:
        raise ValueError(f"successes must be in [0, {trials}], got {successes}")
    n = float(trials)
    p = successes / n
    z2 = z * z
    denom = 1.0 + z2 / n
    centre = (p + z2 / (2.0 * n)) / denom
    half = z * math.sqrt(p * (1.0 - p) / n + z2 / (4.0 * n * n)) / denom
    lower = 0.0 if successes == 0 else max(0.0, centre - half)
    upper = 1.0 if successes == trials else min(1.0, centre + half)
    return (lower, upper)


def _stats(values: Sequence[float]) -> dict[str, Any]:
    vals = [v for v in values if isinstance(v, (int, float)) and math.isfinite(v)]
    if not vals:
        return {"n": 0, "mean": None, "median": None, "min": None, "max": None}
    return {"n": len(vals), "mean": statistics.fmean(vals), "median": statistics.median(vals),
            "min": min(vals), "max": max(vals)}


def summarize(results: Sequence[TrialResult], identity: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The campaign's summary (see the module doc for definitions)."""
    n = len(results)
    ok = sum(r.outcome == "success" for r in results)
    errors = [r for r in results if r.outcome == "error"]
    lo, hi = wilson_interval(ok, n)
    requests = [q for r in results for q in r.requests]
    reasons = Counter(r.reason for r in results if r.outcome != "success")
    causes = Counter(_cause(r) for r in results if r.outcome != "success")
    rec_hist = Counter(r.recoveries for r in results)
    out: dict[str, Any] = {
        "trials": n,
        "successes": ok,
        "failures": sum(r.outcome == "failure" for r in results),
        "errors": len(errors),
        "success_rate": ok / n if n else 0.0,
        "success_rate_ci95": [lo, hi],
        "clock_per_request": _stats([q["duration"] for q in requests]),
        "clock_per_success": _stats([q["duration"] for q in requests if q["outcome"] == "success"]),
        "wall_per_trial": _stats([r.wall for r in results]),
        "failure_reasons": dict(reasons.most_common()),
        "failure_causes": dict(causes.most_common()),
        "recoveries": {str(k): rec_hist[k] for k in sorted(rec_hist)},
        "errored_trials": [{"trial": r.index, "seed": r.seed, "reason": r.reason, "command": r.command}
                           for r in errors],
    }
    panels = _panel_truth(results)
    if panels:
        out["panel_truth"] = panels
    nav = summarize_nav([r.truth for r in results])
    if nav:
        out["nav_truth"] = nav
    if identity is not None:
        out["campaign"] = {k: v for k, v in identity.items() if k != "faults_patches"}
    return out


def _panel_truth(results: Sequence[TrialResult]) -> dict[str, Any]:
    """The control panels' ground truth over the trials that have one (sim/panel.py):
    trials with every light on at the end, switched presses within the tolerance of their
    button's centre, trials with both, and the press offsets [mm]. Empty when no trial
    switched a button: a panel standing in the world of another mission (the fetch in
    ``lab``) is not measured."""
    rows = [r.truth for r in results if r.truth.get("panel_lights")]
    if not any(t.get("panel_presses") for t in rows):
        return {}
    offsets = [p for t in rows for p in t["panel_presses"] if p is not None]
    presses = sum(len(t["panel_presses"]) for t in rows)
    all_on = [t["panel_lights_on"] == t["panel_lights"] for t in rows]
    within = [t["presses_within"] == len(t["panel_presses"]) for t in rows]
    return {
        "trials": len(rows),
        "all_lights_on": sum(all_on),
        "presses": presses,
        "presses_within_5mm": sum(t["presses_within"] for t in rows),
        "trials_all_on_and_within": sum(a and w for a, w in zip(all_on, within)),
        "offset_mm": {"median": statistics.median(offsets) if offsets else None,
                      "p95": sorted(offsets)[min(len(offsets) - 1, math.ceil(0.95 * len(offsets)) - 1)] if offsets else None,
                      "max": max(offsets) if offsets else None},
    }


def _cause(r: TrialResult) -> str:
    """A short, stable label for a non-success: the failure kind and the failing node's
    last path element (or ``error`` for crashed trials)."""
    if r.outcome == "error":
        return "error (crashed trial)"
    node = r.failure_node.rsplit("/", 1)[-1] if r.failure_node else ""
    kind = r.failure_kind or r.outcome
    return f"{kind} @ {node}" if node else kind


def _write_csv(path: Path, results: Sequence[TrialResult]) -> None:
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(_CSV_FIELDS)
        for r in results:
            reqs = "; ".join(", ".join(f"{k}={v}" for k, v in (q.get("request") or {}).items()) or "-"
                             for q in r.requests)
            w.writerow([r.index, r.seed, r.outcome, reqs, f"{r.clock:.3f}", f"{r.wall:.3f}", r.recoveries,
                        r.reason, r.failure_kind, r.failure_node, "" if r.exit_code is None else r.exit_code,
                        r.command])


def _fmt(x: Any, unit: str = " s") -> str:
    return "-" if x is None else f"{x:.1f}{unit}"


def _plots(out_dir: Path, results: Sequence[TrialResult], summary: Mapping[str, Any],
           compare: Sequence[tuple[str, Mapping[str, Any]]]) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    written: list[str] = []
    ok_t = [q["duration"] for r in results for q in r.requests if q["outcome"] == "success"]
    bad_t = [q["duration"] for r in results for q in r.requests if q["outcome"] != "success"]
    fig, ax = plt.subplots(figsize=(6.4, 3.6))
    if ok_t or bad_t:
        ax.hist([ok_t, bad_t], bins=20, stacked=True, label=["success", "not success"], color=["#2a7", "#c44"])
        ax.legend()
    ax.set_xlabel("mission time per request [clock s]")
    ax.set_ylabel("requests")
    ax.set_title(f"Mission time ({len(ok_t) + len(bad_t)} requests)")
    fig.tight_layout()
    fig.savefig(out_dir / "mission_time.png", dpi=100)
    plt.close(fig)
    written.append("mission_time.png")

    causes = list(summary["failure_causes"].items())[:12]
    fig, ax = plt.subplots(figsize=(6.4, 0.6 + 0.4 * max(1, len(causes))))
    if causes:
        labels = [c if len(c) <= 45 else c[:44] + "…" for c, _ in causes][::-1]
        ax.barh(labels, [n for _, n in causes][::-1], color="#c44")
        ax.set_xlabel("trials")
    else:
        ax.text(0.5, 0.5, "no failures", ha="center", va="center", transform=ax.transAxes)
        ax.set_yticks([])
    ax.set_title("Failure causes")
    fig.tight_layout()
    fig.savefig(out_dir / "failure_causes.png", dpi=100)
    plt.close(fig)
    written.append("failure_causes.png")

    if compare:
        rows = [("this campaign", summary)] + list(compare)
        names = [_label(name, s) for name, s in rows]
        rates = [s["success_rate"] for _, s in rows]
        lo = [max(0.0, s["success_rate"] - s["success_rate_ci95"][0]) for _, s in rows]
        hi = [max(0.0, s["success_rate_ci95"][1] - s["success_rate"]) for _, s in rows]
        fig, ax = plt.subplots(figsize=(6.4, 3.6))
        ax.bar(range(len(rows)), rates, yerr=[lo, hi], capsize=6, color="#48c")
        ax.set_xticks(range(len(rows)), names, fontsize=8)
        ax.set_ylim(0.0, 1.05)
        ax.set_ylabel("success rate (95% Wilson CI)")
        ax.set_title("Success rate by campaign")
        fig.tight_layout()
        fig.savefig(out_dir / "success_rate.png", dpi=100)
        plt.close(fig)
        written.append("success_rate.png")
    return written


def _label(name: str, s: Mapping[str, Any]) -> str:
    c = s.get("campaign", {})
    rec = "recovery" if c.get("recovery", True) else "no recovery"
    return f"{name}\n{c.get('faults', '?')}, {rec}"


def _report(identity: Mapping[str, Any], summary: Mapping[str, Any], results: Sequence[TrialResult],
            plots: Sequence[str], compare: Sequence[tuple[str, Mapping[str, Any]]]) -> str:
    lo, hi = summary["success_rate_ci95"]
    c = summary["clock_per_request"]
    cs = summary["clock_per_success"]
    w = summary["wall_per_trial"]
    lines = [
        f"# Campaign: {identity.get('mission')} on {identity.get('config')}",
        "",
        (f"- trials: {summary['trials']} (seed {identity.get('seed')}; trial i runs with seed "
        "`trial_seed(S, i)`, see docs/campaigns.md)"),
        (f"- fault profile: `{identity.get('faults')}` ({identity.get('faults_description', '')}); "
        f"recovery {'on' if identity.get('recovery', True) else 'OFF (ablation)'}; world randomisation "
        f"{'on' if identity.get('randomize') else 'off' if identity.get('randomize') is False else 'n/a'}"),
        f"- requests: {identity.get('requests_description', '')}",
        "",
        "## Results",
        "",
        "| measure | value |",
        "|---|---|",
        (f"| success rate | **{summary['success_rate']:.3f}** ({summary['successes']}/{summary['trials']}), "
        f"95% Wilson CI [{lo:.3f}, {hi:.3f}] |"),
        f"| failures / errors (crashed trials) | {summary['failures']} / {summary['errors']} |",
        f"| clock time per request, mean / median | {_fmt(c['mean'])} / {_fmt(c['median'])} ({c['n']} requests) |",
        f"| clock time per successful request, mean / median | {_fmt(cs['mean'])} / {_fmt(cs['median'])} |",
        f"| wall time per trial, mean / median | {_fmt(w['mean'])} / {_fmt(w['median'])} |",
        "",
        "Recoveries used per trial: " + (", ".join(f"{k}: {v}" for k, v in summary["recoveries"].items()) or "-"),
        "",
    ]
    pt = summary.get("panel_truth")
    if pt:
        o = pt["offset_mm"]
        lines += ["## Control panel (ground truth)", "", "| measure | value |", "|---|---|",
                  f"| trials with every light on at the end | {pt['all_lights_on']}/{pt['trials']} |",
                  f"| switched presses within 5 mm of the button centre | {pt['presses_within_5mm']}/{pt['presses']} |",
                  f"| trials with every light on and every press within 5 mm | {pt['trials_all_on_and_within']}/{pt['trials']} |",
                  (f"| press offset from the centre, median / p95 / max | {_fmt(o['median'], ' mm')} / "
                  f"{_fmt(o['p95'], ' mm')} / {_fmt(o['max'], ' mm')} |"), ""]
    lines += nav_report_lines(summary.get("nav_truth", {}))
    if summary["failure_reasons"]:
        lines += ["## Failure reasons", "", "| trials | reason |", "|---:|---|"]
        lines += [f"| {n} | {reason.replace('|', '/')} |" for reason, n in summary["failure_reasons"].items()]
        lines.append("")
    if compare:
        lines += ["## Comparison", "", "| campaign | faults | recovery | trials | success rate | 95% CI |",
                  "|---|---|---|---:|---:|---|"]
        for name, s in [("this campaign", summary), *compare]:
            cc = s.get("campaign", {})
            a, b = s["success_rate_ci95"]
            lines.append(f"| {name} | {cc.get('faults', '?')} | {'on' if cc.get('recovery', True) else 'off'} | "
                         f"{s['trials']} | {s['success_rate']:.3f} | [{a:.3f}, {b:.3f}] |")
        lines.append("")
    failed = [r for r in results if r.outcome != "success"]
    if failed:
        lines += ["## Trials that did not succeed (reproduce alone with the command)", ""]
        for r in failed[:50]:
            lines.append(f"- trial {r.index:04d} ({r.outcome}): {r.reason}  \n  `{r.command}`")
        if len(failed) > 50:
            lines.append(f"- ... and {len(failed) - 50} more (trials.csv)")
        lines.append("")
    lines += ["## Plots", ""] + [f"![{p}]({p})" for p in plots] + [""]
    return "\n".join(lines)


def write_outputs(out_dir: Path, identity: Mapping[str, Any], results: Sequence[TrialResult], *,
                  compare: Sequence[Path] = ()) -> dict[str, Any]:
    """Write summary.json, trials.csv, report.md and the plots into ``out_dir``;
    ``compare`` lists other campaign directories (their summary.json) to set beside
    this one. Returns the summary."""
    summary = summarize(results, identity)
    others: list[tuple[str, Mapping[str, Any]]] = []
    for other in compare:
        others.append((str(other), json.loads((Path(other) / "summary.json").read_text())))
    if others:
        summary["compared_with"] = [{"dir": name, "faults": s.get("campaign", {}).get("faults"),
                                     "recovery": s.get("campaign", {}).get("recovery"), "trials": s["trials"],
                                     "success_rate": s["success_rate"], "success_rate_ci95": s["success_rate_ci95"]}
                                    for name, s in others]
    fruit = summarize_fruit(out_dir, results)  # the pick_fruit figures, from the trials' truth and logs
    if fruit is not None:
        summary["fruit"] = fruit
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    _write_csv(out_dir / "trials.csv", results)
    plots = _plots(out_dir, results, summary, others)
    report = _report(identity, summary, results, plots, others)
    if fruit is not None:
        report = report.rstrip("\n") + "\n" + "\n".join(fruit_report_lines(fruit)) + "\n"
    (out_dir / "report.md").write_text(report)
    return summary
