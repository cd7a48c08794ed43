"""``foreach`` (a child run once per list element, the element bound to a blackboard
key) and ``if``/``then``/``else`` (a condition picks a branch, as BT.CPP's IfThenElse)."""

from __future__ import annotations

import pytest
from py_trees.common import Status
from test_nodes_support import Harness

from mmexec.executive.compiler import MissionTree

S, F, R, I = Status.SUCCESS, Status.FAILURE, Status.RUNNING, Status.INVALID


def _each_tick(h: Harness, t: MissionTree, key: str, limit: int = 20) -> tuple[list[Status], list[object]]:
    """Tick ``t`` until it finishes: the statuses, and blackboard key ``key`` after each tick."""
    statuses: list[Status] = []
    values: list[object] = []
    while not statuses or statuses[-1] is R:
        assert len(statuses) < limit, "still running"
        statuses.append(t.tick())
        values.append(t.rt.bb.get(key))
        h.robot.spin(0.1)
    return statuses, values


FOREACH_PLACES = """
    params:
      places: {type: list, default: [shelf, table, depot]}
    tree:
      foreach: "{places}"
      as: place
      do:
        skill: succeed
        name: visit
        params: {value: "at {place}"}
        outputs: {value: where}
"""


# ------------------------------------------------------------------------ foreach


def test_foreach_runs_the_child_once_per_element_one_run_per_tick(h):
    t = h.tree(FOREACH_PLACES)
    assert _each_tick(h, t, "where") == ([R, R, S], ["at shelf", "at table", "at depot"])
    assert t.blackboard()["place"] == "depot"  # the key keeps the last element
    assert [(f["index"], f["count"]) for e, f in h.events if e == "foreach_item"] == [(0, 3), (1, 3), (2, 3)]
    assert h.names("foreach_item") == ["m", "m", "m"]


def test_foreach_over_a_parameter_given_by_the_run(h):
    t = h.tree(FOREACH_PLACES, params={"places": "[home]"})
    assert _each_tick(h, t, "where") == ([S], ["at home"])


def test_foreach_over_an_empty_list_succeeds_at_once_without_running_the_child(h):
    t = h.tree(FOREACH_PLACES, params={"places": []})
    assert h.run(t) == (S, 1)
    assert h.journal == [] and "place" not in t.blackboard()


def test_foreach_over_a_request_field_and_a_literal_list_nested(h):
    t = h.tree("""
        requests:
          items: list
        tree:
          foreach: "{request.items}"
          as: item
          do:
            foreach: [a, b]
            as: side
            do: {skill: succeed, name: pick, params: {value: "{item:02d}{side}"}, outputs: {value: picked}}
    """, request={"items": [3, 7]})
    assert _each_tick(h, t, "picked") == ([R, R, R, S], ["03a", "03b", "07a", "07b"])


def test_foreach_over_a_blackboard_value_written_by_a_skill(h):
    t = h.tree("""
        tree:
          sequence:
            - skill: succeed
              params: {value: [1, 2]}
              outputs: {value: found}
            - foreach: "{found}"
              as: marker
              do: {skill: succeed, name: approach, params: {value: "{marker}"}, outputs: {value: at}}
    """)
    # the writer succeeds at once: the first element runs in the same tick
    assert _each_tick(h, t, "at") == ([R, S], [1, 2])


def test_foreach_fails_at_the_first_failed_run_and_skips_the_rest(h):
    t = h.tree("""
        tree:
          foreach: [s, f, s]
          as: outcome
          do: {skill: script, params: {counter: runs, outcomes: "{outcome}"}}
    """)
    assert h.run(t) == (F, 4)  # a scripted run takes two ticks
    assert h.ctx.world["runs"] == 2
    assert t.blackboard()["outcome"] == "f"


def test_foreach_starts_again_from_the_first_element_on_each_activation(h):
    t = h.tree("""
        tree:
          repeat:
            foreach: [1, 2]
            as: n
            do: {skill: succeed, name: step, params: {value: "{n}"}, outputs: {value: got}}
          times: 2
    """)
    assert _each_tick(h, t, "got") == ([R, R, R, S], [1, 2, 1, 2])


def test_halting_a_foreach_halts_its_running_child_and_restarts_the_list(h):
    t = h.tree("""
        tree:
          foreach: [a, b]
          as: x
          do: {skill: hold, params: {stop_ticks: 2}}
    """)
    assert h.ticks(t, 2) == [R, R]
    t.request_halt()
    assert h.ticks(t, 3) == [R, R, I]
    assert [e for _, e in h.journal] == ["start", "cancel", "stopped"]
    assert t.root.status is I


def test_foreach_whose_value_is_not_a_list_at_run_time_fails_as_a_precondition(h):
    t = h.tree("""
        tree:
          sequence:
            - skill: succeed
              params: {value: 3}
              outputs: {value: found}
            - foreach: "{found}"
              as: marker
              do: {skill: succeed}
    """)
    assert h.run(t)[0] is F
    bb = t.blackboard()
    assert bb["last_failure_kind"] == "precondition" and bb["last_failure_node"] == "m/foreach"
    assert bb["last_failure"] == "foreach: expected a list, got int 3"


def test_foreach_over_a_key_not_written_yet_fails_as_a_precondition(h):
    t = h.tree("""
        tree:
          fallback:
            - sequence:
                - skill: fail
                - skill: succeed
                  params: {value: [1]}
                  outputs: {value: found}
            - foreach: "{found}"
              as: marker
              do: {skill: succeed}
    """)
    assert h.run(t)[0] is F
    assert t.blackboard()["last_failure"] == "foreach: blackboard key 'found' is not set (nothing wrote it yet)"


def test_foreach_reuses_an_included_subtree_with_a_recovery_per_element(h):
    # fetch A then B with one approach subtree: the recovery's bookkeeping is per run
    h.write("approach.yaml", """
        params:
          item: {type: int}
        tree:
          recovery:
            action: {skill: script, params: {counter: "approach-{item}", outcomes: fs}}
            recovery: {skill: succeed}
            max_recoveries: 1
          name: approach
    """)
    t = h.tree("""
        requests:
          items: list
        tree:
          foreach: "{request.items}"
          as: item
          do:
            include: approach.yaml
            params: {item: "{item}"}
    """, request={"items": [4, 9]})
    attempts: list[int] = []
    t.add_status_listener(lambda path, old, new: attempts.append(t.rt.bb["approach.attempts"])
                          if path == "m/approach" and new == "SUCCESS" else None)
    assert h.run(t)[0] is S
    assert attempts == [2, 2]
    assert h.ctx.world == {"journal": h.journal, "approach-4": 2, "approach-9": 2}


@pytest.mark.parametrize(("body", "where", "message"), [
    ("foreach: [1]\n  do: {skill: succeed}\n", "5:3",
     "foreach: missing required key 'as' (the blackboard key each element is written to)"),
    ("foreach: [1]\n  as: x\n", "5:3", "foreach: missing required key 'do' (the node run once per element)"),
    ("foreach: 3\n  as: x\n  do: {skill: succeed}\n", "5:12",
     "foreach: expected a list or a reference to one like '{request.items}', got an integer"),
    ("foreach: places\n  as: x\n  do: {skill: succeed}\n", "5:12",
     "foreach: expected a list or a reference to one like '{request.items}', got 'places'"),
    ('foreach: "{n}"\n  as: x\n  do: {skill: succeed}\n', "5:12", "foreach: expected a list, but '{n}' is int"),
    ('foreach: "{places} and more"\n  as: x\n  do: {skill: succeed}\n', "5:12",
     "foreach: expected a list, but '{places} and more' is str"),
    ("foreach: [1]\n  as: n\n  do: {skill: succeed}\n", "6:7",
     "foreach.as: 'n' is a parameter of this file: '{n}' would read the parameter, not the element"),
    ("foreach: [1]\n  as: request.item\n  do: {skill: succeed}\n", "6:7",
     "foreach.as: key 'request.item' is reserved (written by the executive)"),
    ("foreach: [1]\n  as: 'two words'\n  do: {skill: succeed}\n", "6:7",
     "foreach.as: expected a blackboard key name, got 'two words'"),
    ("foreach: [1]\n  as: x\n  do: [{skill: succeed}]\n", "7:7",
     "foreach.do: expected one child node, got a list (wrap the list in a sequence)"),
    ("foreach: [1]\n  as: x\n  do: {skill: succeed}\n  in: [2]\n", "8:3", "unknown key 'in' for foreach (expected one of: as, do, name)"),
])
def test_foreach_mistakes_are_located_errors(h, body, where, message):
    header = "params:\n  n: {type: int, default: 1}\n  places: {type: list, default: []}\n"
    assert h.problems(header + "tree:\n  " + body) == [f"{h.tmp / 'm.yaml'}:{where}: {message}"]


def test_foreach_over_a_blackboard_key_of_another_type_is_a_located_error(h):
    lines = h.problems("""
        tree:
          sequence:
            - skill: flaky
              params: {fail_times: 0}
              outputs: {runs: runs}
            - foreach: "{runs}"
              as: x
              do: {skill: succeed}
    """)
    assert lines == [f"{h.tmp / 'm.yaml'}:7:16: foreach expects a list, but '{{runs}}' is int"]


def test_a_nested_foreach_may_not_rebind_the_enclosing_key(h):
    lines = h.problems("""
        tree:
          foreach: [1, 2]
          as: item
          do:
            foreach: [3]
            as: item
            do: {skill: succeed}
    """)
    assert lines == [(f"{h.tmp / 'm.yaml'}:7:9: foreach.as: 'item' is already bound by the enclosing foreach "
                     f"at {h.tmp / 'm.yaml'}:4:7; use another name")]


def test_the_element_type_of_a_literal_list_is_checked_against_skill_parameters(h):
    lines = h.problems("""
        tree:
          foreach: [a, b]
          as: t
          do: {skill: succeed, params: {ticks: "{t}"}}
    """)
    assert lines == [f"{h.tmp / 'm.yaml'}:5:40: skill 'succeed': parameter 'ticks' expects int, but '{{t}}' is str"]


# ------------------------------------------------------------------------ if / then / else

IF_ELSE = """
    requests:
      n: int
    tree:
      if: {condition: request.n, op: ">", value: 2}
      then: {skill: succeed, name: big, params: {ticks: 1}}
      else: {skill: succeed, name: small}
"""


@pytest.mark.parametrize(("n", "branch", "ticks"), [(5, "m/big", 2), (1, "m/small", 1)])
def test_if_runs_then_when_the_condition_succeeds_else_when_it_fails(h, n, branch, ticks):
    t = h.tree(IF_ELSE, request={"n": n})
    assert h.run(t) == (S, ticks)
    assert [p for p, e in h.journal if e == "start"] == [branch]


def test_if_without_else_fails_when_the_condition_fails(h):
    t = h.tree("""
        tree:
          if: {skill: fail}
          then: {skill: succeed}
    """)
    assert h.run(t) == (F, 1)
    assert [p for p, e in h.journal if e == "start"] == ["m/fail"]


def test_the_branch_status_is_the_node_status(h):
    t = h.tree("""
        tree:
          if: {skill: fail}
          then: {skill: succeed}
          else: {skill: fail, name: fallback_failed, params: {reason: "else failed"}}
    """)
    assert h.run(t) == (F, 1)
    assert t.blackboard()["last_failure"] == "else failed"


def test_if_waits_for_a_running_condition_and_does_not_tick_it_again_while_the_branch_runs(h):
    t = h.tree("""
        tree:
          if: {skill: succeed, name: check, params: {ticks: 2}}
          then: {skill: hold, params: {ticks: 3}}
    """)
    assert h.ticks(t, 3) == [R, R, R]
    assert h.run(t) == (S, 3)
    assert [(p, e) for p, e in h.journal] == [("m/check", "start"), ("m/check", "success"),
                                              ("m/hold", "start"), ("m/hold", "success")]


def test_halting_an_if_halts_the_running_branch(h):
    t = h.tree("""
        tree:
          if: {condition: last_failure, op: exists}
          then: {skill: succeed}
          else: {skill: hold, params: {stop_ticks: 1}}
    """)
    assert h.ticks(t, 2) == [R, R]
    t.request_halt()
    assert h.ticks(t, 2) == [R, I]
    assert [e for _, e in h.journal] == ["start", "cancel", "stopped"]


def test_an_if_picks_again_on_each_activation(h):
    t = h.tree("""
        tree:
          repeat:
            if: {skill: script, params: {counter: cond, outcomes: sf}}
            then: {skill: succeed, name: picked_then}
            else: {skill: succeed, name: picked_else}
          times: 2
    """)
    assert h.run(t)[0] is S
    assert [p for p, e in h.journal if e == "start" and p != "m/if/script"] == ["m/if/picked_then", "m/if/picked_else"]


@pytest.mark.parametrize(("body", "where", "message"), [
    ("if: {condition: x, op: exists}\n  else: {skill: succeed}\n", "2:3",
     "if: missing required key 'then' (the node run when the condition succeeds)"),
    ("if: {condition: x, op: exists}\n  then: [{skill: succeed}]\n", "3:9",
     "if.then: expected one child node, got a list (wrap the list in a sequence)"),
    ("if: {condition: x, op: exists}\n  then: {skill: succeed}\n  elif: {skill: succeed}\n", "4:3",
     "unknown key 'elif' for if (expected one of: then, else, name)"),
    ("if:\n  then: {skill: succeed}\n", "2:6", "if: expected a child node, got nothing"),
])
def test_if_mistakes_are_located_errors(h, body, where, message):
    assert f"{h.tmp / 'm.yaml'}:{where}: {message}" in h.problems("tree:\n  " + body)
