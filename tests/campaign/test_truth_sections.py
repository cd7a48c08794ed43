"""The campaign report's control-panel and fruit sections count only what a mission did:
a fetch campaign in a world that also holds a panel and a plant reports neither (it showed
"every light on 0/200" before), a press or pick campaign reports them."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

from mmexec.executive.campaign.fruittruth import summarize_fruit
from mmexec.executive.campaign.report import _panel_truth


def _panel(presses: list[float | None], on: int) -> SimpleNamespace:
    return SimpleNamespace(truth={"panel_presses": presses, "panel_lights": 3, "panel_lights_on": on,
                                  "presses_within": sum(1 for p in presses if p is not None and p <= 5.0)})


def test_panel_section_only_when_a_button_was_switched() -> None:
    assert _panel_truth([_panel([], 0), _panel([], 0)]) == {}  # the panel stood there, nobody pressed
    pt = _panel_truth([_panel([0.4, 1.2, 6.0], 3), _panel([], 0)])
    assert pt["trials"] == 2 and pt["all_lights_on"] == 1
    assert pt["presses"] == 3 and pt["presses_within_5mm"] == 2
    assert pt["offset_mm"]["max"] == 6.0


def _fruit_trial(tmp: Path, seed: int, states: list[str], choices: int) -> SimpleNamespace:
    (tmp / "truth").mkdir(exist_ok=True)
    recs = [{"event": "fruit_start", "fruit": [{"name": f"f{k}", "label": "apple", "centre": [1.0, 1.0, 0.8]}
                                               for k in range(len(states))]}]
    recs += [{"event": "fruit", "t": 5.0, "name": f"f{k}", "state": s} for k, s in enumerate(states) if s != "plant"]
    (tmp / "truth" / f"{seed}.jsonl").write_text("".join(json.dumps(r, separators=(",", ":")) + "\n" for r in recs))
    log = tmp / f"{seed}.log.jsonl"
    looks = [{"event": "fruit_detections", "t": 1.0 + k, "detections": [], "chosen": None} for k in range(choices)]
    log.write_text("".join(json.dumps(r, separators=(",", ":")) + "\n" for r in looks))
    return SimpleNamespace(index=seed, seed=seed, log=str(log))


def test_fruit_section_only_when_a_fruit_was_looked_for_or_moved(tmp_path: Path) -> None:
    untouched = [_fruit_trial(tmp_path, 1, ["plant", "plant"], 0), _fruit_trial(tmp_path, 2, ["plant"], 0)]
    assert summarize_fruit(tmp_path, untouched) is None
    picked = [_fruit_trial(tmp_path, 3, ["held", "plant"], 0)]
    fr = summarize_fruit(tmp_path, picked)
    assert fr is not None and fr["trials"] == 1 and fr["picked"] == 1 and fr["fruit"] == 2
