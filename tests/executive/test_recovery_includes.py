"""A file with a recovery included more than once: the second and later includes get
their own namespace for the recovery's blackboard keys (the include's name), the first
keeps the keys it always had; a genuine clash of names stays an error."""

from __future__ import annotations

import pytest
from py_trees.common import Status
from test_nodes_support import Harness

from mmexec.config.yamlload import InputError

S, F = Status.SUCCESS, Status.FAILURE

#: fails ``fails`` times (its counter is per item), the recovery reports, the bookkeeping
#: is read inside the file (a skill parameter, a template, a condition)
APPROACH = """
    params:
      item: {type: int}
      fails: {type: int, default: 0}
    tree:
      sequence:
        - recovery:
            action: {skill: flaky, params: {counter: "approach-{item}", fail_times: "{fails}"}}
            recovery:
              skill: succeed
              params: {ticks: "{approach.recoveries}", value: "retry {approach.recoveries:d}: {approach.last_failure}"}
              outputs: {value: note}
            max_recoveries: 2
          name: approach
        - condition: approach.outcome
          op: "=="
          value: success
"""


@pytest.fixture
def h(tmp_path):
    h = Harness(tmp_path)
    h.write("approach.yaml", APPROACH)
    return h


#: a mission including approach.yaml twice, the second as ``again`` (more steps may follow)
TWICE = """
    tree:
      sequence:
        - include: approach.yaml
          params: {item: 1}
        - include: approach.yaml
          name: again
          params: {item: 2}
"""

FETCH_A_THEN_B = """
    tree:
      sequence:
        - include: approach.yaml
          params: {item: 1}
        - include: approach.yaml
          name: approach_b
          params: {item: 2, fails: 1}
        - skill: succeed
          name: summary
          params: {value: "{approach.attempts} then {approach_b.approach.attempts}: {approach_b.approach.outcome}"}
          outputs: {value: summary}
"""


def test_a_second_include_writes_the_recovery_keys_under_its_name(h):
    t = h.tree(FETCH_A_THEN_B)
    assert h.run(t)[0] is S
    bb = t.blackboard()
    # the first include keeps the keys a single include always had
    assert {k: bb[k] for k in bb if k.startswith("approach.")} == {
        "approach.attempts": 1, "approach.recoveries": 0, "approach.last_failure": "", "approach.outcome": "success"}
    assert {k: bb[k] for k in bb if k.startswith("approach_b.")} == {
        "approach_b.approach.attempts": 2, "approach_b.approach.recoveries": 1,
        "approach_b.approach.last_failure": "flaky failure (run 1)", "approach_b.approach.outcome": "success"}
    # inside the second include, the file's own references read its own keys
    assert bb["note"] == "retry 1: flaky failure (run 1)"  # written by the second include only
    assert bb["summary"] == "1 then 2: success"


def test_each_include_has_its_own_node_paths_and_events(h):
    t = h.tree(FETCH_A_THEN_B)
    assert h.run(t)[0] is S
    paths = [p for p, _ in t.snapshot()]
    assert "m/approach/sequence/approach" in paths and "m/approach_b/sequence/approach" in paths
    assert h.names("recovery_attempt") == ["m/approach_b/sequence/approach"]
    assert h.names("recovery_success") == ["m/approach/sequence/approach", "m/approach_b/sequence/approach"]


def test_an_unnamed_second_include_is_namespaced_by_the_file_name(h):
    t = h.tree("""
        tree:
          sequence:
            - include: approach.yaml
              params: {item: 1, fails: 1}
            - include: approach.yaml
              params: {item: 2}
    """)
    assert h.run(t)[0] is S
    bb = t.blackboard()
    assert (bb["approach.attempts"], bb["approach.approach.attempts"]) == (2, 1)
    assert [p for p, _ in t.snapshot() if p.endswith("/sequence/approach")] == [
        "m/approach/sequence/approach", "m/approach#2/sequence/approach"]


def test_the_including_file_reads_a_namespaced_key_that_exists_and_is_told_about_one_that_does_not(h):
    lines = h.problems(TWICE + """        - condition: again.approach.outcom
          op: exists
    """)
    assert lines == [(f"{h.tmp / 'm.yaml'}:9:18: blackboard key 'again.approach.outcom' is read but nothing writes it; "
                     "did you mean 'again.approach.outcome'? (a skill output, request.<field>, a parameter, or "
                     "recovery bookkeeping)")]


def test_a_namespaced_key_has_its_type_for_checks(h):
    lines = h.problems(TWICE + """        - skill: succeed
          params: {ticks: "{again.approach.outcome}", value: "{again.approach.attempts:.2f} {again.approach.outcome:d}"}
    """)
    assert len(lines) == 2, lines
    assert lines[0].endswith("skill 'succeed': parameter 'ticks' expects int, but '{again.approach.outcome}' is str")
    assert lines[1].endswith("format spec ':d' cannot format a str: Unknown format code 'd' for object of type 'str' "
                             "(blackboard key 'again.approach.outcome' is str)")


def test_a_file_that_includes_the_file_is_namespaced_with_its_references(h):
    # wrapper includes approach.yaml once and reads its outcome; the mission includes
    # approach.yaml itself, then the wrapper: the wrapper's whole subtree is namespaced
    h.write("wrapper.yaml", """
        tree:
          sequence:
            - include: approach.yaml
              params: {item: 7, fails: 2}
            - skill: succeed
              params: {value: "{approach.outcome} after {approach.attempts}"}
              outputs: {value: wrapped}
    """)
    t = h.tree("""
        tree:
          sequence:
            - include: approach.yaml
              params: {item: 1}
            - include: wrapper.yaml
              name: twice
    """)
    assert h.run(t)[0] is S
    bb = t.blackboard()
    assert bb["approach.attempts"] == 1 and bb["twice.approach.attempts"] == 3
    assert bb["wrapped"] == "success after 3"


def test_namespaces_nest_when_a_file_with_a_second_include_is_included_twice(h):
    h.write("pair.yaml", """
        params:
          base: {type: int}
        tree:
          sequence:
            - include: approach.yaml
              params: {item: "{base}"}
            - include: approach.yaml
              name: second
              params: {item: 100, fails: 1}
    """)
    t = h.tree("""
        tree:
          sequence:
            - include: pair.yaml
              params: {base: 1}
            - include: pair.yaml
              name: other
              params: {base: 2}
    """)
    assert h.run(t)[0] is S
    outcomes = {k: v for k, v in t.blackboard().items() if k.endswith(".outcome")}
    assert outcomes == {"approach.outcome": "success", "second.approach.outcome": "success",
                        "other.approach.outcome": "success", "other.second.approach.outcome": "success"}
    # counters are per item: item 100 runs in both pairs (1 failure, then a success each time)
    assert h.ctx.world["approach-100"] == 3


def test_a_third_include_under_a_namespace_already_taken_is_a_located_error(h):
    lines = h.problems(TWICE + """        - sequence:
            - include: approach.yaml
              name: again
              params: {item: 3}
    """)
    assert len(lines) == 1, lines
    assert lines[0].startswith(f"{h.tmp / 'm.yaml'}:10:11: include 'approach.yaml': 'again.approach' is already in "
                               f"the tree (recovery at {h.tmp / 'approach.yaml'}:7:7): it brings the recovery "
                               f"'approach' at {h.tmp / 'approach.yaml'}:7:7 again, so its recovery keys go under the "
                               "include's name; give this include a distinct `name:`")


def test_a_namespace_that_cannot_start_a_key_is_a_located_error(h):
    lines = h.problems("""
        tree:
          sequence:
            - include: approach.yaml
              params: {item: 1}
            - include: approach.yaml
              name: 2nd
              params: {item: 2}
    """)
    assert lines == [(f"{h.tmp / 'm.yaml'}:6:7: include 'approach.yaml': the include's name '2nd' cannot start a "
                     f"blackboard key: it brings the recovery 'approach' at {h.tmp / 'approach.yaml'}:7:7 again, so "
                     "its recovery keys go under the include's name; give this include a `name:` (a letter or _ first)")]


def test_a_genuine_clash_through_an_include_is_still_refused(h):
    lines = h.problems("""
        tree:
          sequence:
            - recovery: {action: {skill: succeed}, recovery: {skill: succeed}, max_recoveries: 1}
              name: approach
            - include: approach.yaml
              params: {item: 1}
            - include: approach.yaml
              name: again
              params: {item: 2}
    """)
    # the first include clashes with the mission's own 'approach'; the second too (its
    # keys would be namespaced only if the first had been accepted)
    assert [ln.split(": ", 1)[0].rsplit(":", 2)[1:] for ln in lines] == [["6", "7"], ["8", "7"]]
    assert all("its recovery 'approach' at" in ln and "is already in the tree (recovery at" in ln for ln in lines)
    assert all(ln.endswith("give each recovery a distinct `name:`") for ln in lines)


def test_the_shipped_fetch_mission_keeps_its_keys_and_paths():
    # fetch_item includes fetch/approach.yaml once: no namespace, the keys its conditions
    # and reports read are the ones the recoveries write
    from mmexec.executive.compiler import TREES_DIR, load_mission
    from mmexec.executive.config import load_skill_modules
    from mmexec.executive.nodes import Condition, Recovery

    load_skill_modules(None)  # the built-in skills the mission uses (localize too), as a run loads them
    t = load_mission(TREES_DIR / "fetch_item.yaml").display_tree()
    recoveries = {n.path: n.k_outcome for n in t.nodes() if isinstance(n, Recovery)}
    # fetch/drive.yaml (issue 11) is included five times: the first keeps its keys, the
    # others are namespaced by their include's name
    assert recoveries == {"fetch_item/pick_item": "pick_item.outcome",
                          "fetch_item/pick_item/sequence/approach/approach": "approach.outcome",
                          "fetch_item/pick_item/sequence/approach/approach/sequence#2/go_home/sequence/drive/drive":
                              "drive.outcome",
                          "fetch_item/pick_item/sequence#2/go_home/sequence/drive/drive": "go_home.drive.outcome",
                          "fetch_item/pick_item/sequence#3/home_after_give_up/sequence/drive/drive":
                              "home_after_give_up.drive.outcome",
                          "fetch_item/to_depot/drive": "to_depot.drive.outcome",
                          "fetch_item/return_home/drive": "return_home.drive.outcome"}
    # the approach's holistic fallback reads the failure kind the approach left (a global
    # key, not a recovery's); fetch_item's retry reads whether the approach gave up
    assert [n.key for n in t.nodes() if isinstance(n, Condition)] == ["last_failure_kind", "approach.outcome"]


def test_the_fetch_a_then_b_example_of_missions_md_compiles_and_its_error_is_the_documented_one(tmp_path):
    import re
    import shutil

    from mmexec.executive.compiler import TREES_DIR, load_mission
    from mmexec.executive.config import load_skill_modules
    from mmexec.executive.nodes import Recovery

    load_skill_modules(None)  # the built-in skills the example uses (localize too), as a run loads them
    doc = (TREES_DIR.parent / "docs" / "missions.md").read_text()
    block = re.search(r"```yaml\n(mission: fetch_two.*?)```", doc, re.DOTALL)
    sample = re.search(r"^trees/fetch_two\.yaml:\d+:\d+: .*$", doc, re.MULTILINE)
    assert block is not None and sample is not None
    shutil.copytree(TREES_DIR / "fetch", tmp_path / "fetch")
    mission = tmp_path / "fetch_two.yaml"
    mission.write_text(block.group(1))
    t = load_mission(mission).display_tree()
    assert {n.k_outcome for n in t.nodes() if isinstance(n, Recovery)} >= {"approach.outcome", "approach_b.approach.outcome"}
    third = "    - include: fetch/approach.yaml\n      name: approach_b\n      params: {item: 1}\n"
    mission.write_text(block.group(1).replace("    - skill: report", third + "    - skill: report"))
    with pytest.raises(InputError) as ei:
        load_mission(mission)
    assert str(ei.value).replace(f"{tmp_path}/", "trees/") == sample.group(0)
