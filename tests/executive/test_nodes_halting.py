"""The halt contract: cancelled exactly once, deepest first, multi-tick stops never block."""

from __future__ import annotations

from py_trees.common import Status

S, F, R, I = Status.SUCCESS, Status.FAILURE, Status.RUNNING, Status.INVALID


def test_reactive_sequence_guard_failure_halts_running_action_over_3_ticks(h):
    t = h.tree("""
        requests:
          go: bool
        tree:
          sequence:
            - condition: request.go
              op: "=="
              value: true
            - skill: hold
              name: arm
              params: {stop_ticks: 3}
          reactive: true
    """, request={"go": True})
    assert h.ticks(t, 2) == [R, R]
    t.rt.bb["request.go"] = False  # the guard now fails
    sts = h.ticks(t, 4)
    # cancel on the first tick, 3 stopping ticks, FAILURE once stopped; the parent stays RUNNING meanwhile
    assert sts == [R, R, R, F]
    assert [e for _, e in h.journal] == ["start", "cancel", "stopped"]
    assert h.names("skill_cancel") == ["m/arm"]
    stopped = [f for e, f in h.events if e == "skill_stopped"]
    assert stopped[0]["ticks"] == 3
    assert t.snapshot()[-1] == ("m/arm", "INVALID")


def test_memory_sequence_does_not_re_evaluate_guard(h):
    t = h.tree("""
        requests:
          go: bool
        tree:
          sequence:
            - condition: request.go
              op: "=="
              value: true
            - skill: hold
              params: {ticks: 3}
    """, request={"go": True})
    h.ticks(t, 1)
    t.rt.bb["request.go"] = False
    assert h.run(t) == (S, 3)
    assert "cancel" not in [e for _, e in h.journal]


def test_reactive_fallback_higher_priority_preempts_lower(h):
    t = h.tree("""
        tree:
          fallback:
            - sequence:
                - condition: alarm
                  op: exists
                - skill: succeed
                  name: handle
                  params: {ticks: 1}
            - skill: hold
              name: work
              params: {stop_ticks: 2}
            - skill: succeed
              outputs: {value: alarm}
          reactive: true
    """)
    assert h.ticks(t, 2) == [R, R]
    t.rt.bb["alarm"] = 1
    sts = h.ticks(t, 3)
    # tick 1: 'handle' starts (RUNNING) -> preempts 'work' (cancel); tick 2: work still stopping, 'handle'
    # is not ticked; tick 3: work stopped, the fallback resumes its own logic in the same tick and
    # ticks 'handle' again, which succeeds
    assert sts == [R, R, S]
    assert h.journal == [("m/work", "start"), ("m/sequence/handle", "start"), ("m/work", "cancel"),
                         ("m/work", "stopped"), ("m/sequence/handle", "success")]
    assert [e for p, e in h.journal if p == "m/work"] == ["start", "cancel", "stopped"]
    assert h.names("skill_cancel") == ["m/work"]


def test_halt_is_deepest_first_and_exactly_once(h):
    t = h.tree("""
        tree:
          parallel:
            - sequence:
                - parallel:
                    - skill: hold
                      name: a
                      params: {stop_ticks: 2}
                    - skill: hold
                      name: b
                      params: {stop_ticks: 1}
                  name: inner
              name: left
            - skill: hold
              name: c
    """)
    t.tick()
    t.request_halt()
    order = []
    t.add_status_listener(lambda p, o, n: order.append((p, n)) if n == "INVALID" else None)
    sts = []
    for _ in range(5):
        sts.append(t.tick())
    assert sts == [R, R, I, I, I]
    assert t.stopped
    # every hold cancelled exactly once (no "cancel-again"), children stop before their parents
    cancels = [(p, e) for p, e in h.journal if e.startswith("cancel")]
    assert cancels == [("m/left/inner/a", "cancel"), ("m/left/inner/b", "cancel"), ("m/c", "cancel")]
    stopped = [p for p, _ in order]
    assert stopped.index("m/left/inner/a") < stopped.index("m/left/inner") < stopped.index("m/left") < stopped.index("m")
    assert stopped.index("m/left/inner/b") < stopped.index("m/left/inner")
    assert stopped.index("m/c") < stopped.index("m")
    assert len(stopped) == len(set(stopped))
    assert h.names("skill_cancel") == ["m/left/inner/a", "m/left/inner/b", "m/c"]


def test_halt_while_a_preemption_is_already_stopping(h):
    t = h.tree("""
        tree:
          timeout:
            parallel:
              - skill: hold
                name: slow
                params: {stop_ticks: 4}
              - skill: fail
                params: {ticks: 1}
          seconds: 100
    """)
    assert h.ticks(t, 3) == [R, R, R]  # fail at tick 2 -> 'slow' is stopping
    t.request_halt()
    sts = [t.tick() for _ in range(4)]
    assert sts == [R, R, I, I]
    assert [e for p, e in h.journal if p == "m/parallel/slow"] == ["start", "cancel", "stopped"]


def test_halt_of_finished_tree_is_immediate(h):
    t = h.tree("""
        tree:
          skill: succeed
    """)
    assert t.tick() is S
    t.request_halt()
    assert t.stopped and t.tick() is I
    assert h.names("skill_cancel") == []


def test_retry_halt_stops_child_and_resets(h):
    t = h.tree("""
        tree:
          retry: {skill: hold, params: {stop_ticks: 1}}
          attempts: 3
    """)
    h.ticks(t, 2)
    t.request_halt()
    assert [t.tick(), t.tick()] == [R, I]
    assert [e for _, e in h.journal] == ["start", "cancel", "stopped"]


def test_halting_skill_that_stops_at_once(h):
    t = h.tree("""
        tree:
          sequence:
            - skill: hold
    """)
    t.tick()
    t.request_halt()
    assert t.tick() is I
    assert [e for _, e in h.journal] == ["start", "cancel", "stopped"]
    assert [f["ticks"] for e, f in h.events if e == "skill_stopped"] == [0]
