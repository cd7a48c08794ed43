"""Display: the text tree (kinds, skill parameters, conditions, recovery and if
branches), dot export named by node paths in plain-ASCII labels, and a clean error when
Graphviz is missing."""

from __future__ import annotations

import re
import shutil

import py_trees
import pydot
import pytest

from mmexec.executive import display

MISSION = """
mission: shown
tree:
  sequence:
    - skill: succeed
      name: first
    - fallback: [{skill: fail}, {skill: hold}]
      reactive: true
"""

BRANCHES = """
mission: branches
requests:
  item: {type: int}
params:
  label: {type: str, default: "a box"}
tree:
  sequence:
    - recovery:
        action:
          skill: fail
          name: grasp
          params: {reason: "closed on {request.item:03d}", ticks: 2}
        recovery: {wait: 1.5}
        give_up:
          skill: succeed
          params: {value: "{label}"}
        max_recoveries: 2
      name: pick
    - if: {condition: request.item, op: in, value: [1, 2, 3]}
      then: {skill: succeed, name: shelf, params: {value: "{request.item}"}}
      else:
        invert: {condition: pick.outcome, op: exists}
    - timeout: {retry: {skill: hold}, attempts: 3}
      seconds: 20
"""


def test_render_text_of_mission_and_ticked_tree(h):
    m = h.load(MISSION)
    text = display.render_text(m)
    assert text.splitlines() == ["{-} shown", "    --> first  succeed()", "    [o] fallback",
                                 "        --> fail  fail()", "        --> hold  hold()"]
    t = m.instantiate(h.ctx, {})
    t.tick()
    live = display.render_text(t)
    assert "first [✓]  succeed()" in live and "fail [✕]" in live and "hold [*]" in live


def test_text_labels_branches_and_shows_parameters_and_conditions(h):
    assert display.render_text(h.load(BRANCHES)).splitlines() == [
        "{-} branches",
        "    (R) pick  recovery, at most 2 recoveries",
        '        action: --> grasp  fail(reason="closed on {request.item:03d}", ticks=2)',
        "        recovery: --> wait  wait 1.5 s",
        '        give_up: --> succeed  succeed(value="a box")',
        "    (?) if",
        "        if: --> condition  request.item in [1, 2, 3]",
        "        then: --> shelf  succeed(value={request.item})",
        "        else: -^- invert",
        "            --> condition  pick.outcome exists",
        "    -^- timeout  timeout 20 s",
        "        -^- retry  retry, at most 3 attempts",
        "            --> hold  hold()",
    ]


#: pydot's dot parser (used to read the written file back) calls deprecated pyparsing names
PARSES_DOT = pytest.mark.filterwarnings("ignore::DeprecationWarning:pydot.dot_parser")


def dot_graph(h, text):
    """The dot file of ``text``, parsed back (so its quoting is valid dot)."""
    return pydot.graph_from_dot_data(display.to_dot(h.load(text)).to_string())[0]


@PARSES_DOT
def test_dot_nodes_are_named_by_node_paths_with_labelled_branches(h):
    m = h.load(BRANCHES)
    graph = dot_graph(h, BRANCHES)
    paths = [path for path, _status in m.display_tree().snapshot()]
    assert sorted(n.get_name().strip('"') for n in graph.get_nodes() if n.get_name() not in ("node", "edge")) == \
        sorted(paths)
    edges = {(e.get_source().strip('"'), e.get_destination().strip('"')): (e.get_label() or "").strip('"')
             for e in graph.get_edges()}
    assert edges[("branches/pick", "branches/pick/grasp")] == "action"
    assert edges[("branches/pick", "branches/pick/wait")] == "recovery"
    assert edges[("branches/pick", "branches/pick/succeed")] == "give_up"
    assert [edges[("branches/if", f"branches/if/{c}")] for c in ("condition", "shelf", "invert")] == \
        ["if", "then", "else"]
    assert edges[("branches", "branches/pick")] == ""
    grasp = next(n for n in graph.get_nodes() if n.get_name() == '"branches/pick/grasp"')
    assert grasp.get_label() == '"grasp\\nfail(reason=\\"closed on {request.item:03d}\\", ticks=2)"'
    assert grasp.get("tooltip") == '"branches/pick/grasp"'


def test_dot_labels_are_plain_ascii_in_a_standard_font(h):
    """The default Graphviz font lacks py_trees' symbols (the memory mark, status ticks):
    they rendered as boxes. Every character the dot file asks Graphviz to draw is now
    ASCII (for an ASCII mission), in Helvetica."""
    for text in (MISSION, BRANCHES):
        source = display.to_dot(h.load(text)).to_string()
        assert source.isascii(), [c for c in source if not c.isascii()]
        for symbol in py_trees.display.unicode_symbols.values():
            if not symbol.isascii():
                assert symbol not in source
        assert re.search(r"node \[fontname=Helvetica", source)
        assert "times-roman" not in source and "Ⓜ" not in source


@PARSES_DOT
def test_user_text_cannot_become_a_dot_escape(h):
    m = h.load('mission: q\ntree:\n  skill: fail\n  params: {reason: "a \\\\N \\" b"}\n')
    source = display.to_dot(m).to_string()
    assert '(reason=\\"a \\\\\\\\N \\\\\\" b\\")' in source  # the value's quotes and backslash escaped
    graph = pydot.graph_from_dot_data(source)[0]
    assert [n.get_name() for n in graph.get_nodes() if n.get_name() not in ("node", "edge")] == ['"q"']


def test_write_dot(h, tmp_path):
    out = display.write_dot(h.load(MISSION), tmp_path / "t.dot")
    text = out.read_text()
    assert text.startswith("digraph") and '"shown/first"' in text and '"shown/fallback"' in text and "->" in text


def test_write_svg_without_graphviz_is_a_one_line_error(h, tmp_path, monkeypatch):
    monkeypatch.setattr(shutil, "which", lambda name: None)
    with pytest.raises(display.DisplayError) as ei:
        display.write_svg(h.load(MISSION), tmp_path / "t.svg")
    assert "Graphviz 'dot' is not installed" in str(ei.value) and "\n" not in str(ei.value)
    assert not (tmp_path / "t.svg").exists()
