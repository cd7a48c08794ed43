"""Fruit picking as a campaign measures it (issue 14, ``trees/pick_fruit.yaml``).

Two sources per trial, as for navigation (:mod:`.navtruth` when present):

* the ground-truth sidecar ``DIR/truth/SEED.jsonl`` (:mod:`mmexec.sim.truth`; a sim
  campaign writes one per trial): ``fruit_start`` lists every fruit on the plants, and a
  ``fruit`` record marks each change of a fruit's true state (``plant``, ``held``,
  ``robot_basket``, ``depot:NAME``, ``floor``, ``loose``). A fruit is **picked** when the
  gripper held it (state ``held``), **knocked off** when it left the plant otherwise,
  **in a basket** when it was picked and its last state is ``robot_basket`` or a depot's. Every fruit on the plant counts as reachable: the world hangs them only on the
  plant's side the robot works from, at 0.4-1.2 m (docs/fruit.md);
* the trial's event log: each ``fruit_detections`` record (skills/fruit/pick.py) lists
  the detections of one look with their confidence ``c`` and distance ``z``, and the
  index the skill chose. :func:`choice_measures` recomputes Algorithm 1.3's score
  ``s = c/4 + 3/4 (z_max - z)/z_max`` (z_max 1.5 m) for each and checks that the chosen
  one has the highest, and, with the truth, that the next fruit to leave the plant after
  that look is the chosen one (its true hanging centre within 3 cm of the chosen
  barycentre).

:func:`summarize_fruit` folds the trials into the summary (``summary.json`` key
``fruit``) and :func:`fruit_report_lines` into report.md. None when no trial has fruit, or
no trial looked for or moved one (a plant in another mission's world).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

__all__ = ["choice_measures", "fruit_report_lines", "summarize_fruit", "truth_fruit"]

#: Algorithm 1.3's z_max [m]
Z_MAX = 1.5
#: [m] the chosen barycentre and the true centre of the fruit that came off agree within this
SAME_FRUIT = 0.03
BASKET_STATES = ("robot_basket",)


def truth_fruit(path: Path) -> dict[str, Any] | None:
    """One trial's fruit truth: ``fruit`` {name: {label, centre, final, off_t}} (``off_t``
    the clock time it left the plant, None if it did not), ``depots`` (the states that
    are baskets). None when the sidecar has no ``fruit_start``."""
    fruit: dict[str, dict[str, Any]] = {}
    seen = False
    with path.open() as f:
        for line in f:
            if line.startswith('{"event":"fruit_start"'):
                seen = True
                for fr in json.loads(line).get("fruit", ()):
                    fruit[fr["name"]] = {"label": fr["label"], "centre": fr["centre"], "final": "plant", "off_t": None,
                                         "held": False}
            elif line.startswith('{"event":"fruit",'):
                rec = json.loads(line)
                fr = fruit.get(rec["name"])
                if fr is None:
                    continue
                fr["final"] = rec["state"]
                fr["held"] = fr.get("held", False) or rec["state"] == "held"
                if fr["off_t"] is None and rec["state"] != "plant":
                    fr["off_t"] = float(rec["t"])
    return {"fruit": fruit} if seen else None


def _score(c: float, z: float) -> float:
    return 0.25 * c + 0.75 * (Z_MAX - z) / Z_MAX


def choice_measures(log_path: Path, truth: dict[str, Any] | None) -> dict[str, int]:
    """Counts over the trial's ``fruit_detections`` records with a choice: ``choices``,
    ``highest`` (the chosen detection has the highest recomputed score), ``checked``
    (a fruit left the plant after the look), ``matched`` (it was the chosen one)."""
    out = {"choices": 0, "highest": 0, "checked": 0, "matched": 0}
    offs = sorted((fr["off_t"], fr["centre"]) for fr in (truth or {}).get("fruit", {}).values()
                  if fr["off_t"] is not None)
    looks = []
    with log_path.open() as f:
        for line in f:
            if '"event":"fruit_detections"' not in line:
                continue
            rec = json.loads(line)
            if rec.get("chosen") is None:
                continue
            looks.append(rec)
    for i, rec in enumerate(looks):
        dets = rec["detections"]
        k = int(rec["chosen"])
        scores = [_score(float(d["confidence"]), float(d["z"])) for d in dets]
        out["choices"] += 1
        out["highest"] += scores[k] >= max(scores) - 1e-9
        t0 = float(rec["t"])
        t1 = float(looks[i + 1]["t"]) if i + 1 < len(looks) else math.inf
        nxt = next((c for t, c in offs if t0 <= t < t1), None)
        if nxt is not None:
            out["checked"] += 1
            ch = dets[k]["centre"]
            out["matched"] += math.dist(ch, nxt) <= SAME_FRUIT
    return out


def summarize_fruit(out_dir: Path, results: Sequence[Any]) -> dict[str, Any] | None:
    """The campaign's fruit figures over ``results`` (TrialResults: seed, log), from
    ``out_dir/truth/SEED.jsonl`` and each trial's event log; None when no trial has a
    fruit truth, or when no trial looked for fruit or moved one (a plant standing in the
    world of another mission, the fetch in ``lab``, is not measured)."""
    trials = []
    for r in results:
        path = out_dir / "truth" / f"{r.seed}.jsonl"
        if not path.is_file():
            continue
        truth = truth_fruit(path)
        if truth is None or not truth["fruit"]:
            continue
        fr = truth["fruit"].values()
        n = len(fr)
        picked = sum(f["held"] for f in fr)
        knocked = sum(f["off_t"] is not None and not f["held"] for f in fr)
        basket = sum(f["held"] and (f["final"] in BASKET_STATES or f["final"].startswith("depot:")) for f in fr)
        log = Path(r.log)
        ch = choice_measures(log, truth) if log.is_file() else {"choices": 0, "highest": 0, "checked": 0, "matched": 0}
        trials.append({"trial": r.index, "seed": r.seed, "fruit": n, "picked": picked, "knocked_off": knocked,
                       "in_basket": basket, **ch})
    if not any(t["choices"] or t["picked"] or t["knocked_off"] for t in trials):
        return None
    tot = {k: sum(t[k] for t in trials) for k in ("fruit", "picked", "knocked_off", "in_basket", "choices", "highest",
                                                   "checked", "matched")}
    per_trial = [t["picked"] / t["fruit"] for t in trials]
    return {
        "trials": len(trials),
        **tot,
        "picked_fraction_per_trial": {"min": min(per_trial), "mean": sum(per_trial) / len(per_trial)},
        "trials_at_least_90pct_picked": sum(p >= 0.9 - 1e-9 for p in per_trial),
        "in_basket_of_picked": tot["in_basket"] / tot["picked"] if tot["picked"] else None,
        "chosen_highest_priority": tot["highest"] / tot["choices"] if tot["choices"] else None,
        "chosen_was_picked": tot["matched"] / tot["checked"] if tot["checked"] else None,
        "per_trial": trials,
    }


def fruit_report_lines(fruit: dict[str, Any]) -> list[str]:
    """report.md's section on the fruit (Markdown lines)."""
    def pct(x: float | None) -> str:
        return "n/a" if x is None else f"{100 * x:.1f} %"

    worst = [t for t in fruit["per_trial"] if t["picked"] < t["fruit"] or t["in_basket"] < t["picked"]]
    head = "| trial | seed | fruit | picked | knocked off | in basket |"
    lines = [
        "",
        "## Fruit (ground truth + event log)",
        "",
        (f"- trials with fruit: {fruit['trials']}; fruit on the plants: {fruit['fruit']}, picked (held and pulled "
         f"off): {fruit['picked']}, in a basket: {fruit['in_basket']}, knocked off: {fruit['knocked_off']}"),
        (f"- reachable fruit picked per trial: mean {pct(fruit['picked_fraction_per_trial']['mean'])}, "
        f"min {pct(fruit['picked_fraction_per_trial']['min'])}; trials with >= 90 %: "
        f"{fruit['trials_at_least_90pct_picked']}/{fruit['trials']}"),
        f"- picked fruit in a basket: {pct(fruit['in_basket_of_picked'])}",
        (f"- choices of the highest-priority detection (Algorithm 1.3, recomputed): {fruit['highest']}/"
        f"{fruit['choices']}; the fruit that came off was the chosen one: {fruit['matched']}/{fruit['checked']}"),
    ]
    if worst:
        lines += ["", head, "|---|---|---|---|---|---|"]
        lines += [f"| {t['trial']} | {t['seed']} | {t['fruit']} | {t['picked']} | {t['knocked_off']} | {t['in_basket']} |"
                  for t in worst]
    return lines
