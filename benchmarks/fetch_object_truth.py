"""Score a fetch_object campaign against the simulator's ground truth (issue 15).

    python benchmarks/fetch_object_truth.py DIR [DIR ...]

DIR is a campaign directory run with ``--faults benchmarks/campaigns/objects_truth.yaml``
(so each trial's ground truth is in ``DIR/truth/SEED.jsonl``). For every trial it reads
the requested item (``DIR/trials.csv``), the trial's outcome, and the truth log's
``grasp`` records (sim/truth.py: which parts of an object the gripper's pads touched when
they closed on it) and ``objects_end`` record (where each object ended up: in the depot
basket or not, the delivery the mission's own outcome cannot see). A trial of a dangerous item (an object with a part sim/objects.py
marks dangerous) counts as *on the dangerous part* when the pick's grasp of that item
touched that part: the last grasp before the trial's first ``place`` started (its event log
``DIR/trials/NNNN.jsonl``; the same sim clock), not a close of ``place``'s own check that
caught the released item; without the log, the last grasp. Prints one line per item and the totals; the last line is
``dangerous_part_contact: X`` (fraction of the dangerous-item trials).
"""

from __future__ import annotations

import csv
import json
import math
import sys
from collections import defaultdict
from pathlib import Path

from mmexec.config.yamlload import load_yaml
from mmexec.sim.world import load_world


def _in_depot(campaign: Path, xyz: list[float]) -> bool:
    """Whether a point [m] in map lies in one of the world's depot baskets (inside the walls,
    below the rim + 5 cm), as SimTruth.in_depot tests it."""
    cfg = load_yaml(campaign / "config.yaml")
    world = load_world(str(cfg["sim"].get("world", "lab")))
    for d in world.spec.depots:
        c, s = math.cos(d.pose[2]), math.sin(d.pose[2])
        dx, dy = xyz[0] - d.pose[0], xyz[1] - d.pose[1]
        lx, ly = c * dx + s * dy, -s * dx + c * dy
        if abs(lx) < d.size[0] / 2 and abs(ly) < d.size[1] / 2 and xyz[2] < d.size[2] + 0.05:
            return True
    return False


def _place_start(log: Path) -> float | None:
    """Sim time [s] at which the trial's first ``place`` skill started; None without one."""
    if not log.is_file():
        return None
    for line in log.read_text().splitlines():
        rec = json.loads(line)
        if rec.get("event") == "skill_start" and rec.get("skill") == "place":
            return float(rec["t"])
    return None


def score(campaign: Path) -> tuple[dict[str, list[int]], int, int]:
    """Per item: [trials, successes, dangerous-part contacts, in the basket by the truth];
    and the dangerous trials and contacts over all items."""
    dangerous = _dangerous_parts(campaign)
    rows: dict[str, list[int]] = defaultdict(lambda: [0, 0, 0, 0])
    n_dangerous = hits = 0
    with (campaign / "trials.csv").open() as f:
        for row in csv.DictReader(f):
            item = row["requests"].partition("item=")[2].split()[0] if "item=" in row["requests"] else ""
            r = rows[item]
            r[0] += 1
            r[1] += row["outcome"] == "success"
            truth = campaign / "truth" / f"{row['seed']}.jsonl"
            records = list(map(json.loads, truth.read_text().splitlines())) if truth.is_file() else []
            end = next((g for g in records if g.get("event") == "objects_end"), None)
            r[3] += bool(end and item in end["positions"] and _in_depot(campaign, end["positions"][item]))
            if not dangerous.get(item):
                continue
            n_dangerous += 1
            t_place = _place_start(campaign / "trials" / f"{int(row['trial']):04d}.jsonl")
            grasps = [g for g in records if g.get("event") == "grasp" and g.get("item") == item
                      and (t_place is None or float(g.get("t", 0.0)) < t_place)]
            if grasps and dangerous[item] & set(grasps[-1]["parts"]):
                r[2] += 1
                hits += 1
    return dict(rows), n_dangerous, hits


def main(argv: list[str]) -> int:
    if not argv:
        print(__doc__.strip().splitlines()[2].strip(), file=sys.stderr)
        return 2
    total_d = total_h = 0
    for d in map(Path, argv):
        rows, nd, nh = score(d)
        flagged = _dangerous(d)
        print(f"{d}:")
        for item, (n, ok, hit, basket) in sorted(rows.items()):
            extra = f", pads on the dangerous part {hit}/{n}" if item in flagged else ""
            print(f"  {item}: {ok}/{n} succeeded, {basket}/{n} in the basket (truth){extra}")
        total = sum(r[0] for r in rows.values())
        print(f"  all: {sum(r[1] for r in rows.values())}/{total} succeeded, "
              f"{sum(r[3] for r in rows.values())}/{total} in the basket (truth)")
        total_d += nd
        total_h += nh
    frac = total_h / total_d if total_d else float("nan")
    print(f"dangerous-item trials: {total_d}, pads on the dangerous part: {total_h}")
    print(f"dangerous_part_contact: {frac:.3f}")
    return 0


def _dangerous_parts(campaign: Path) -> dict[str, set[str]]:
    """Object name -> its dangerous parts, in the campaign's world."""
    cfg = load_yaml(campaign / "config.yaml")
    world = load_world(str(cfg["sim"].get("world", "lab")))
    return {o.name: {p.name for p in o.model.parts if p.dangerous} for o in world.spec.objects}


def _dangerous(campaign: Path) -> set[str]:
    return {name for name, parts in _dangerous_parts(campaign).items() if parts}


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
