"""The recovery node: exactly N recoveries, give-up, failed recovery, counter resets, records."""

from __future__ import annotations

import pytest
from py_trees.common import Status

S, F, R, I = Status.SUCCESS, Status.FAILURE, Status.RUNNING, Status.INVALID

MISSION = """
tree:
  recovery:
    action: {{skill: script, name: grasp, params: {{counter: action, outcomes: "{action}"}}}}
    recovery: {{skill: script, name: rehome, params: {{counter: recovery, outcomes: "{recovery}"}}}}
    max_recoveries: {n}
    {give_up}
  name: grasp_item
"""
GIVE_UP = "give_up: {skill: script, name: go_home, params: {counter: give_up, outcomes: s}}"


def make(h, action, recovery="s", n=2, give_up=GIVE_UP):
    return h.tree(MISSION.format(action=action, recovery=recovery, n=n, give_up=give_up))


def runs(h, counter):
    return h.ctx.world.get(counter, 0)


@pytest.mark.parametrize("fails", [0, 1, 2])
def test_succeeds_after_k_failures_with_exactly_k_recoveries(h, fails):
    t = make(h, "f" * fails + "s")
    st, _ = h.run(t)
    assert st is S
    assert runs(h, "action") == fails + 1
    assert runs(h, "recovery") == fails
    assert runs(h, "give_up") == 0
    bb = t.blackboard()
    assert bb["grasp_item.attempts"] == fails + 1
    assert bb["grasp_item.recoveries"] == fails
    assert bb["grasp_item.outcome"] == "success"
    assert [f["attempt"] for e, f in h.events if e == "recovery_attempt"] == list(range(1, fails + 1))
    assert t.root.recoveries == 0  # reset on success


def test_bound_spent_runs_give_up_and_fails(h):
    t = make(h, "f")
    st, _ = h.run(t)
    assert st is F
    assert runs(h, "action") == 3  # 1 + max_recoveries
    assert runs(h, "recovery") == 2
    assert runs(h, "give_up") == 1
    bb = t.blackboard()
    assert bb["grasp_item.outcome"] == "gave_up"
    assert bb["grasp_item.last_failure"] == "scripted failure (run 3)"
    assert bb["grasp_item.attempts"] == 3 and bb["grasp_item.recoveries"] == 2
    give = [f for e, f in h.events if e == "recovery_give_up"]
    assert len(give) == 1 and give[0]["node"] == "grasp_item" and give[0]["reason"] == "scripted failure (run 3)"
    assert "t" in give[0]
    assert t.root.recoveries == 0  # reset on give-up


def test_give_up_success_does_not_turn_into_success(h):
    t = make(h, "f", n=0)
    assert h.run(t)[0] is F
    assert runs(h, "action") == 1 and runs(h, "recovery") == 0 and runs(h, "give_up") == 1


def test_no_give_up_subtree(h):
    t = make(h, "f", n=1, give_up="")
    assert h.run(t)[0] is F
    assert runs(h, "action") == 2 and runs(h, "recovery") == 1


def test_failed_recovery_ends_node_at_once_after_give_up(h):
    t = make(h, "f", recovery="f", n=5)
    assert h.run(t)[0] is F
    assert runs(h, "action") == 1
    assert runs(h, "recovery") == 1
    assert runs(h, "give_up") == 1
    assert t.blackboard()["grasp_item.outcome"] == "recovery_failed"
    assert [e for e, _ in h.events if e.startswith("recovery_")] == ["recovery_attempt", "recovery_failed"]


def test_counter_resets_between_activations(h):
    t = h.tree("""
        tree:
          repeat:
            recovery:
              action: {skill: script, params: {counter: action, outcomes: fsfs}}
              recovery: {skill: script, params: {counter: recovery}}
              max_recoveries: 1
            name: r
          times: 2
    """)
    # each activation fails once and recovers once; without the reset the second activation
    # would have no recovery left and give up
    assert h.run(t)[0] is S
    assert runs(h, "action") == 4 and runs(h, "recovery") == 2
    assert t.blackboard()["r.outcome"] == "success"


def test_halt_during_recovery_cancels_it_and_resets(h):
    t = h.tree("""
        tree:
          recovery:
            action: {skill: fail, name: act}
            recovery: {skill: hold, name: rec, params: {stop_ticks: 2}}
            max_recoveries: 2
          name: r
    """)
    assert h.ticks(t, 2) == [R, R]
    assert t.root.recoveries == 1
    t.request_halt()
    assert [t.tick() for _ in range(3)] == [R, R, I]
    assert [e for p, e in h.journal if p == "r/rec"] == ["start", "cancel", "stopped"]
    assert t.root.recoveries == 0
    assert t.blackboard()["r.outcome"] == "halted"


def test_later_nodes_read_the_record(h):
    t = h.tree("""
        tree:
          sequence:
            - force_success:
                recovery:
                  action: {skill: fail, params: {reason: "no IK"}}
                  recovery: {skill: succeed}
                  max_recoveries: 1
                name: grasp
            - condition: grasp.outcome
              op: "=="
              value: gave_up
            - skill: succeed
              params: {value: "gave up after {grasp.attempts} attempts: {grasp.last_failure}"}
              outputs: {value: report}
    """)
    assert h.run(t)[0] is S
    assert t.blackboard()["report"] == "gave up after 2 attempts: no IK"


# ------------------------------------------------------------------ ablation switch


@pytest.mark.parametrize("recovery", ["s", "f"])
def test_recovery_disabled_runs_action_once_then_gives_up(h, recovery):
    h.ctx.recovery_enabled = False
    t = make(h, "fs", recovery=recovery, n=2)
    st, _ = h.run(t)
    # enabled, "fs" would succeed after one recovery; disabled it gives up at once
    assert st is F
    assert runs(h, "action") == 1 and runs(h, "recovery") == 0 and runs(h, "give_up") == 1
    bb = t.blackboard()
    assert bb["grasp_item.outcome"] == "gave_up"
    assert bb["grasp_item.attempts"] == 1 and bb["grasp_item.recoveries"] == 0
    assert [e for e, _ in h.events if e.startswith("recovery_")] == ["recovery_give_up"]
    give = [f for e, f in h.events if e == "recovery_give_up"]
    assert give[0]["max_recoveries"] == 0
    assert t.root.max_recoveries == 2  # the mission's bound is kept; only this run ignores it


def test_recovery_disabled_still_succeeds_when_the_action_does(h):
    h.ctx.recovery_enabled = False
    t = make(h, "s")
    assert h.run(t)[0] is S
    assert runs(h, "action") == 1 and runs(h, "give_up") == 0
    assert t.blackboard()["grasp_item.outcome"] == "success"


def test_recovery_enabled_is_the_default_and_read_per_activation(h):
    assert h.ctx.recovery_enabled is True
    t = make(h, "fs")
    assert h.run(t)[0] is S
    assert runs(h, "action") == 2 and runs(h, "recovery") == 1
    # the same context switched off: the next tree (next request) runs without recovery
    h.ctx.recovery_enabled = False
    h.ctx.world.clear()
    t2 = make(h, "fs")
    assert h.run(t2)[0] is F
    assert runs(h, "action") == 1 and runs(h, "recovery") == 0


# ------------------------------------------------------------------ blackboard key names


def test_unnamed_root_recovery_writes_the_keys_the_compiler_declares(h):
    # the root's display name is the mission's name; its keys still use 'recovery.'
    t = h.tree("""
        mission: fetch
        tree:
          sequence:
            - force_success:
                recovery:
                  action: {skill: fail, params: {reason: "no path"}}
                  recovery: {skill: succeed}
                  max_recoveries: 1
            - skill: succeed
              params: {value: "{recovery.outcome} after {recovery.attempts}: {recovery.last_failure}"}
              outputs: {value: report}
    """)
    assert h.run(t)[0] is S
    assert t.blackboard()["report"] == "gave_up after 2: no path"
    t2 = h.tree("""
        mission: fetch
        tree:
          recovery:
            action: {skill: succeed}
            recovery: {skill: succeed}
            max_recoveries: 1
    """)
    assert t2.root.path == "fetch"
    assert h.run(t2)[0] is S
    assert t2.blackboard()["recovery.outcome"] == "success"
    assert "fetch.outcome" not in t2.blackboard()


RECOVERY = "{{recovery: {{action: {{skill: succeed}}, recovery: {{skill: succeed}}, max_recoveries: 1}}{name}}}"


def _rec(name=None):
    return RECOVERY.format(name=f", name: {name}" if name else "")


def test_two_recoveries_with_one_name_are_a_located_error(h):
    lines = h.problems(f"tree:\n  sequence:\n    - {_rec('grasp')}\n    - {_rec('grasp')}\n")
    assert len(lines) == 1
    assert lines[0].startswith(f"{h.tmp / 'm.yaml'}:4:8: recovery name 'grasp' is already used by the recovery at ")
    assert lines[0].endswith(":3:8; both would write grasp.attempts, grasp.recoveries, grasp.last_failure, "
                             "grasp.outcome: give each recovery a distinct `name:`")


def test_two_unnamed_recoveries_are_an_error_even_when_nested(h):
    text = "tree:\n  recovery:\n    action: " + _rec() + "\n    recovery: {skill: succeed}\n    max_recoveries: 1\n"
    lines = h.problems(text)
    assert len(lines) == 1 and ":3:14: recovery name 'recovery' is already used" in lines[0], lines


def test_distinct_names_and_includes_once_are_fine(h):
    h.write("sub.yaml", f"tree: {_rec('inner')}\n")
    m = h.load(f"tree:\n  sequence:\n    - {_rec('a')}\n    - {_rec('b')}\n    - include: sub.yaml\n    - {_rec()}\n")
    t = m.instantiate(h.ctx, {})
    assert h.run(t)[0] is S
    bb = t.blackboard()
    assert [bb[f"{k}.outcome"] for k in ("a", "b", "inner", "recovery")] == ["success"] * 4


def test_recovery_name_clash_between_includer_and_included_file(h):
    h.write("sub.yaml", f"tree: {_rec('grasp')}\n")
    lines = h.problems(f"tree:\n  sequence:\n    - {_rec('grasp')}\n    - include: sub.yaml\n")
    assert len(lines) == 1 and ":4:7: include 'sub.yaml': its recovery 'grasp'" in lines[0], lines
    assert f"is already in the tree (recovery at {h.tmp / 'm.yaml'}:3:8)" in lines[0]
    assert "included once" not in lines[0]


def test_duplicate_inside_an_included_file_is_reported_once_in_that_file(h):
    h.write("sub.yaml", f"tree:\n  sequence:\n    - {_rec('x')}\n    - {_rec('x')}\n")
    lines = h.problems("tree:\n  include: sub.yaml\n")
    assert len(lines) == 1 and lines[0].startswith(f"{h.tmp / 'sub.yaml'}:4:8: recovery name 'x'"), lines
