"""The local-planner configs are their base configs with the local planner switched on
(docs/algorithms.md, "Navigation stack"): the same robot, world and profile, so campaigns
compare the two navigation stacks and nothing else. A change to a base config must be
made to its local twin too; this test says which lines differ."""

from __future__ import annotations

import difflib
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[3]
LOCAL_LINE = "    local_planner: true           # DWA + CLF-CBF on the lidar costmap (needs the lidar)"
NO_FILTER_LINE = "    safety_filter: false          # the DWA alone (comparison)"

#: (twin, base config, the lines the twin adds below its header comment)
TWINS = [
    ("config/locobot_sim_local.yaml", "config/locobot_sim.yaml", [LOCAL_LINE]),
    ("config/ur5e_sim_local.yaml", "config/ur5e_sim.yaml", [LOCAL_LINE]),
    ("config/ur3e_sim_local.yaml", "config/ur3e_sim.yaml", [LOCAL_LINE]),
    ("benchmarks/nav_configs/locobot_lab_nofilter.yaml", "config/locobot_sim.yaml", [LOCAL_LINE, NO_FILTER_LINE]),
]


def _body(path: Path) -> list[str]:
    """The file's lines from ``backend:`` on (the header comment says what it is)."""
    lines = path.read_text().splitlines()
    return lines[next(i for i, line in enumerate(lines) if line.startswith("backend:")):]


@pytest.mark.parametrize(("twin", "base", "added"), TWINS, ids=[t[0] for t in TWINS])
def test_a_local_planner_config_is_its_base_config_with_the_switch_on(twin, base, added):
    twin_lines, base_lines = _body(REPO / twin), _body(REPO / base)
    assert [line for line in twin_lines if line not in added] == base_lines, (
        f"{twin} differs from {base} beyond {added}: keep the two in step")
    assert all(line in twin_lines for line in added)


#: (corridors config, its lab twin with the local planner on): the same robot and profile,
#: only where the world puts things differs (tests/e2e and campaigns compare the worlds)
CORRIDORS = [
    ("config/locobot_corridors_sim.yaml", "config/locobot_sim_local.yaml"),
    ("config/ur5e_corridors_sim.yaml", "config/ur5e_sim_local.yaml"),
    ("config/ur3e_corridors_sim.yaml", "config/ur3e_sim_local.yaml"),
]
#: the lines a corridors config may change: the world, the home pose, the search
#: locations, the depot stop and release point, and comment lines
WORLD_LINE = re.compile(r"\s+(world: (lab|corridors)$|home: \[|- \[|base: \[|place: \[|#)")


@pytest.mark.parametrize(("corridors", "lab"), CORRIDORS, ids=[c[0] for c in CORRIDORS])
def test_a_corridors_config_is_its_lab_twin_in_another_world(corridors, lab):
    mine, twin = _body(REPO / corridors), _body(REPO / lab)
    changed = []
    for op, i0, i1, j0, j1 in difflib.SequenceMatcher(a=twin, b=mine, autojunk=False).get_opcodes():
        if op != "equal":
            changed += twin[i0:i1] + mine[j0:j1]
    assert not [line for line in changed if not WORLD_LINE.match(line)], (
        f"{corridors} differs from {lab} beyond the world's places: keep the two in step")
    assert "  world: corridors" in mine and LOCAL_LINE in mine
