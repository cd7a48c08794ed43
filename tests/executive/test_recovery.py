"""The recovery node: exactly N recoveries, give-up, failed recovery, counter resets, records."""

from __future__ import annotations

import pytest
from py_trees.common import Status
from test_nodes_support import Harness

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


@pytest.fixture
def h(tmp_path):
    return Harness(tmp_path)


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
