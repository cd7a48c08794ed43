"""Templates with Python format specs (``{heading:.2f}``): parsing, located errors at
load, formatting at instantiate and at run time."""

from __future__ import annotations

import pytest
from py_trees.common import Status

from mmexec.executive.values import (
    MAX_FORMAT_WIDTH,
    BadFormat,
    Const,
    Format,
    Ref,
    ValueSyntaxError,
    format_problem,
    parse_value,
    substitute,
)

S, F = Status.SUCCESS, Status.FAILURE


# ------------------------------------------------------------------------ values


def test_a_reference_with_a_spec_parses_to_a_format():
    e = parse_value("{heading:.2f}", lambda name: False)
    assert isinstance(e, Format) and isinstance(e.expr, Ref) and e.spec == ".2f"
    assert e.eval({"heading": 1.23456}) == "1.23"
    assert parse_value("{x:}", lambda name: False).eval({"x": 7}) == "7"  # an empty spec is str()


def test_fill_align_sign_width_grouping_and_types_are_python_s():
    e = parse_value("[{a:*^9}] {b:+,d} {c:08.3f} {d:x} {e:.0%}", lambda name: False)
    assert e.eval({"a": "mid", "b": 12345, "c": -3.14159, "d": 255, "e": 0.25}) == "[***mid***] +12,345 -003.142 ff 25%"


def test_a_parameter_is_formatted_when_the_tree_is_built():
    e = parse_value("n={n:03d} at {h:.1f}", lambda name: name == "n")
    out = substitute(e, {"n": Const(7)})
    assert out.eval({"h": 0.25}) == "n=007 at 0.2"
    assert substitute(parse_value("{n:>4}", lambda name: True), {"n": Const("ab")}).value == "  ab"


@pytest.mark.parametrize(("text", "message"), [
    ("{h:.2q}", "bad format spec ':.2q' (expected [[fill]align][sign][z][#][0][width][grouping][.precision][type]"),
    ("{h:abc}", "bad format spec ':abc'"),
    ("{h:=s}", "format spec ':=s' cannot format any value"),
    ("{h:,n}", "format spec ':,n' cannot format any value: Cannot specify ',' with 'n'"),
    (f"{{h:{MAX_FORMAT_WIDTH + 1}}}", f"width {MAX_FORMAT_WIDTH + 1} is more than the limit of {MAX_FORMAT_WIDTH}"),
    ("{h:.99999999999f}", "precision 99999999999 is more than the limit"),
    ("{bad key:.2f}", "bad reference '{bad key:.2f}'"),
])
def test_a_bad_spec_is_a_syntax_error(text, message):
    with pytest.raises(ValueSyntaxError) as ei:
        parse_value(text, lambda name: False)
    assert message in str(ei.value)


@pytest.mark.parametrize(("spec", "tp", "problem"), [
    (".2f", float, None),
    (".2f", int, None),
    ("d", int, None),
    ("d", float, "cannot format a float: Unknown format code 'd'"),
    (".2", float, "cannot format an int (accepted as a float): Precision not allowed"),
    (".2f", str, "cannot format a str"),
    (">8", list, "cannot format a list"),
    ("", dict, None),
    (".3", str, None),
])
def test_format_problem_knows_the_declared_type(spec, tp, problem):
    got = format_problem(spec, tp)
    assert (got is None) if problem is None else (got is not None and problem in got), got


def test_a_value_the_spec_cannot_format_raises_bad_format_naming_the_key():
    e = parse_value("{heading:.2f}", lambda name: False)
    with pytest.raises(BadFormat) as ei:
        e.eval({"heading": "north"})
    assert ei.value.reason == ("blackboard key 'heading' = 'north' cannot be formatted with ':.2f' "
                               "(Unknown format code 'f' for object of type 'str')")


# ------------------------------------------------------------------------ missions


def test_a_template_formats_parameters_requests_and_outputs(h):
    t = h.tree("""
        params:
          heading: {type: float, default: 1.5}
        requests:
          item: int
        tree:
          sequence:
            - skill: flaky
              params: {fail_times: 0}
              outputs: {runs: runs}
            - skill: succeed
              params: {value: "item {request.item:03d}: heading {heading:.2f} rad after {runs:>3} run(s)"}
              outputs: {value: text}
    """, request={"item": 7})
    assert h.run(t)[0] is S
    assert t.blackboard()["text"] == "item 007: heading 1.50 rad after   1 run(s)"


def test_a_whole_string_reference_with_a_spec_is_a_string(h):
    t = h.tree("""
        params:
          n: {type: int, default: 3}
        tree: {skill: fail, params: {reason: "{n:02d}"}}
    """)
    assert h.run(t)[0] is F
    assert t.blackboard()["last_failure"] == "03"


def test_a_spec_that_does_not_fit_a_parameter_is_a_located_error(h):
    lines = h.problems("""
        params:
          heading: {type: float, default: 1.5}
        tree:
          skill: succeed
          params: {value: "heading {heading:d}"}
    """)
    assert lines == [(f"{h.tmp / 'm.yaml'}:6:19: skill 'succeed': parameter 'value': format spec ':d' cannot format "
                     "a float: Unknown format code 'd' for object of type 'float' (parameter 'heading' is float)")]


def test_a_spec_that_does_not_fit_a_request_field_or_output_is_a_located_error(h):
    lines = h.problems("""
        requests:
          item: int
        tree:
          sequence:
            - skill: flaky
              outputs: {runs: runs}
            - skill: succeed
              params: {value: "{request.item:.2}"}
            - condition: runs
              op: "=="
              value: "{runs:s}"
    """)
    assert len(lines) == 2, lines
    assert lines[0].startswith(f"{h.tmp / 'm.yaml'}:9:23: skill 'succeed': parameter 'value': format spec ':.2' "
                               "cannot format an int: Precision not allowed")
    assert lines[0].endswith("(blackboard key 'request.item' is int)")
    assert lines[1].startswith(f"{h.tmp / 'm.yaml'}:12:14: condition.value: format spec ':s' cannot format an int")


def test_a_bad_spec_in_a_template_is_a_located_error(h):
    lines = h.problems("""
        tree:
          skill: succeed
          params: {value: "heading {heading:.2q}"}
    """)
    assert lines == [(f"{h.tmp / 'm.yaml'}:4:19: skill 'succeed': parameter 'value': bad format spec ':.2q' "
                     "(expected [[fill]align][sign][z][#][0][width][grouping][.precision][type], e.g. '.2f') "
                     "in '{heading:.2q}'")]


def test_a_value_of_unknown_type_that_the_spec_cannot_format_fails_the_leaf_as_a_precondition(h):
    t = h.tree("""
        tree:
          sequence:
            - skill: succeed
              params: {value: north}
              outputs: {value: heading}
            - skill: succeed
              name: show
              params: {value: "heading {heading:.2f}"}
    """)
    assert h.run(t)[0] is F
    bb = t.blackboard()
    assert bb["last_failure_kind"] == "precondition" and bb["last_failure_node"] == "m/show"
    assert bb["last_failure"] == ("succeed: blackboard key 'heading' = 'north' cannot be formatted with ':.2f' "
                                  "(Unknown format code 'f' for object of type 'str')")


def test_a_condition_whose_value_cannot_be_formatted_fails(h):
    t = h.tree("""
        tree:
          sequence:
            - skill: succeed
              params: {value: north}
              outputs: {value: heading}
            - condition: heading
              op: "=="
              value: "{heading:.1f}"
    """)
    assert h.run(t)[0] is F
