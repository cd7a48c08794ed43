"""Render mission trees: text (``mmexec show``), Graphviz dot and SVG files.

``render_text(mission_or_tree)`` accepts a :class:`~mmexec.executive.compiler.Mission`
(rendered from a display-only tree with default parameters) or a
:class:`~mmexec.executive.compiler.MissionTree` (rendered with current statuses).

Each node is one line (text) or one box (dot): its kind, its name and what it does:

* a skill leaf: the skill and the parameters the mission gives it,
  ``grasp  close_gripper(expect=object)``; a condition: ``request.item in [1, 2, 3]``;
  a wait, a timeout, a retry, a repeat, a foreach, a parallel: their numbers;
* the branches of a ``recovery`` node are labelled ``action:``, ``recovery:`` and
  ``give_up:``, those of ``if`` ``if:``, ``then:`` and ``else:`` (edge labels in dot);
* values are written as in a mission file: ``{key}`` reads the blackboard,
  ``{key:.2f}`` formats it.

The text uses py_trees' symbols (``{-}`` sequence, ``[-]`` reactive sequence, ``{o}`` /
``[o]`` fallback, ``/_/`` parallel, ``-^-`` decorator, ``-->`` leaf) and ``(R)`` for a
recovery node, ``(?)`` for ``if``. Dot nodes are named by their mmexec node path
(``fetch/pick_item/sequence/grasp``, as in the event log), and the labels are plain
text in the dot file's font (Helvetica, which every Graphviz install has), so no
symbol renders as a missing-glyph box. SVG needs Graphviz's ``dot`` program; without it
:func:`write_svg` raises :class:`DisplayError` with a one-line message saying what to
install.
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any

import pydot
from py_trees.common import Status

from mmexec.executive import nodes as N
from mmexec.executive.compiler import Mission, MissionTree
from mmexec.executive.values import Const, DictExpr, Expr, Format, ListExpr, ParamRef, Ref, Template

__all__ = ["FONT", "DisplayError", "describe", "render_text", "to_dot", "write_dot", "write_svg"]

#: The dot file's font: one of Graphviz's standard PostScript fonts, so the layout's text
#: widths are known without fontconfig and every SVG viewer has a match.
FONT = "Helvetica"

#: py_trees' status symbols (as in ``mmexec log replay``).
STATUS_SYMBOLS = {Status.SUCCESS: "✓", Status.FAILURE: "✕", Status.RUNNING: "*", Status.INVALID: "-"}

#: (text symbol, dot shape, dot style, dot fill colour) per kind of node
_STYLE: dict[str, tuple[str, str, str, str]] = {
    "sequence": ("{-}", "box", "filled", "orange"),
    "reactive sequence": ("[-]", "box", "filled", "orange"),
    "fallback": ("{o}", "octagon", "filled", "cyan"),
    "reactive fallback": ("[o]", "octagon", "filled", "cyan"),
    "parallel": ("/_/", "parallelogram", "filled", "gold"),
    "recovery": ("(R)", "box3d", "filled", "plum"),
    "if": ("(?)", "diamond", "filled", "lightblue"),
    "decorator": ("-^-", "ellipse", "filled", "ghostwhite"),
    "leaf": ("-->", "box", "rounded,filled", "gray90"),
}


class DisplayError(OSError):
    """A tree could not be rendered (e.g. Graphviz missing)."""


def _tree(obj: Mission | MissionTree) -> MissionTree:
    if isinstance(obj, Mission):
        return obj.display_tree()
    return obj


# --------------------------------------------------------------------------- what a node is


def value_text(expr: Expr) -> str:
    """A mission value as written in a mission file (strings quoted when they hold
    spaces or punctuation, references in braces)."""
    if isinstance(expr, Const):
        return _literal(expr.value)
    if isinstance(expr, (Ref, ParamRef, Format)):
        return "{" + _reference(expr) + "}"
    if isinstance(expr, Template):
        text = "".join(p.replace("{", "{{").replace("}", "}}") if isinstance(p, str) else "{" + _reference(p) + "}"
                       for p in expr.parts)
        return json.dumps(text, ensure_ascii=False)
    if isinstance(expr, ListExpr):
        return "[" + ", ".join(value_text(i) for i in expr.items) + "]"
    if isinstance(expr, DictExpr):
        return "{" + ", ".join(f"{k}: {value_text(v)}" for k, v in expr.items.items()) + "}"
    raise TypeError(f"no display for a mission value of type {type(expr).__name__}")


def _reference(expr: Expr) -> str:
    """The inside of ``{...}``: a blackboard key or parameter, with a format spec."""
    if isinstance(expr, Format):
        return f"{_reference(expr.expr)}:{expr.spec}"
    if isinstance(expr, Ref):
        return expr.key
    if isinstance(expr, ParamRef):
        return expr.name
    raise TypeError(f"no display for a reference of type {type(expr).__name__}")


def _literal(value: Any) -> str:
    if isinstance(value, bool) or value is None:
        return json.dumps(value)
    if isinstance(value, str):
        plain = value and all(c.isalnum() or c in "_.-/" for c in value)
        return value if plain else json.dumps(value, ensure_ascii=False)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_literal(v) for v in value) + "]"
    if isinstance(value, Mapping):
        return "{" + ", ".join(f"{k}: {_literal(v)}" for k, v in value.items()) + "}"
    return format(value, ".15g") if isinstance(value, float) else repr(value)


def _kind(node: Any) -> str:
    """The key of ``node`` in :data:`_STYLE`."""
    for cls, kind in ((N.Sequence, "sequence"), (N.Fallback, "fallback")):
        if isinstance(node, cls):
            return f"reactive {kind}" if node.reactive else kind
    if isinstance(node, N.Parallel):
        return "parallel"
    if isinstance(node, N.Recovery):
        return "recovery"
    if isinstance(node, N.IfThenElse):
        return "if"
    return "leaf" if not node.children else "decorator"


def _skill_call(node: Any) -> str:
    return f"{node.spec.name}(" + ", ".join(f"{k}={value_text(v)}" for k, v in node.params.items()) + ")"


def _comparison(node: Any) -> str:
    return f"{node.key} exists" if node.op == "exists" else f"{node.key} {node.op} {value_text(node.value)}"


#: (node class, what it does) in the order they are tried; the first match describes
_DESCRIPTIONS: tuple[tuple[type, Callable[[Any], str]], ...] = (
    (N.SkillLeaf, _skill_call),
    (N.Condition, _comparison),
    (N.Wait, lambda n: f"wait {value_text(n.seconds)} s"),
    (N.Timeout, lambda n: f"timeout {value_text(n.seconds)} s"),
    (N.Retry, lambda n: f"retry, at most {n.attempts} attempts"),
    (N.Repeat, lambda n: "repeat forever" if n.times is None else f"repeat {n.times} times"),
    (N.Foreach, lambda n: f"foreach {value_text(n.items)} as {n.key}"),
    (N.Parallel, lambda n: f"parallel, succeeds when {n.threshold} of {len(n.children)} succeed"),
    (N.Recovery, lambda n: f"recovery, at most {n.max_recoveries} recoveries"),
    (N.Subtree, lambda n: "include"),
    (N.Invert, lambda n: "invert"),
    (N.ForceSuccess, lambda n: "force_success"),
    (N.ForceFailure, lambda n: "force_failure"),
)


def describe(node: Any) -> str:
    """What ``node`` does, in one line ("" for a plain sequence or fallback)."""
    for cls, what in _DESCRIPTIONS:
        if isinstance(node, cls):
            return what(node)
    return ""


def _detail(node: Any) -> str:
    """:func:`describe`, or "" when that only repeats the node's name (``invert``)."""
    what = describe(node)
    return "" if what == node.name else what


def _branches(node: Any) -> list[tuple[str, Any]]:
    """``(label, child)`` for each child: the branch names of a recovery node and of
    ``if``, "" for the children of any other node."""
    if isinstance(node, N.Recovery):
        named = [("action", node.action), ("recovery", node.recovery), ("give_up", node.give_up)]
    elif isinstance(node, N.IfThenElse):
        named = [("if", node.condition), ("then", node.then), ("else", node.orelse)]
    else:
        return [("", c) for c in node.children]
    return [(label, child) for label, child in named if child is not None]


def _walk(root: Any) -> Iterator[tuple[Any, Any | None, str, int]]:
    """``(node, parent, branch label, depth)`` for every node, depth-first pre-order."""
    stack: list[tuple[Any, Any | None, str, int]] = [(root, None, "", 0)]
    while stack:
        node, parent, label, depth = stack.pop()
        yield node, parent, label, depth
        stack.extend((child, node, lab, depth + 1) for lab, child in reversed(_branches(node)))


# --------------------------------------------------------------------------- text


def render_text(obj: Mission | MissionTree, show_status: bool | None = None) -> str:
    """The tree as text, one node per line (see the module doc). Statuses are shown
    for a MissionTree that has been ticked (``show_status`` forces either way)."""
    tree = _tree(obj)
    if show_status is None:
        show_status = isinstance(obj, MissionTree) and any(n.status is not Status.INVALID for n in tree.nodes())
    lines = []
    for node, _parent, label, depth in _walk(tree.root):
        status = f" [{STATUS_SYMBOLS[node.status]}]" if show_status else ""
        what = _detail(node)
        lines.append("    " * depth + (f"{label}: " if label else "") + f"{_STYLE[_kind(node)][0]} {node.name}{status}"
                     + (f"  {what}" if what else ""))
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- dot, svg


def _quoted(text: str) -> str:
    """``text`` as a dot string: backslashes and quotes escaped, so user text cannot
    become a dot escape (``\\N``, ``\\l``)."""
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def to_dot(obj: Mission | MissionTree) -> pydot.Dot:
    """The tree as a ``pydot.Dot`` graph: one node per tree node, named by its node
    path; its label is its name and, on a second line, what it does."""
    graph = pydot.Dot("mission", graph_type="digraph", ordering="out", rankdir="LR")
    graph.set_node_defaults(fontname=FONT, fontsize="10")
    graph.set_edge_defaults(fontname=FONT, fontsize="9")
    for node, parent, label, _depth in _walk(_tree(obj).root):
        _symbol, shape, style, colour = _STYLE[_kind(node)]
        what = _detail(node)
        text = _quoted(node.name + ("\n" + what if what else "")).replace("\n", "\\n")
        graph.add_node(pydot.Node(_quoted(node.path), label=text, shape=shape, style=_quoted(style),
                                  fillcolor=colour, tooltip=_quoted(node.path)))
        if parent is not None:
            edge = pydot.Edge(_quoted(parent.path), _quoted(node.path))
            if label:
                edge.set_label(_quoted(label))
            graph.add_edge(edge)
    return graph


def write_dot(obj: Mission | MissionTree, path: str | Path) -> Path:
    """Write the tree as a Graphviz dot file; returns the path."""
    p = Path(path)
    p.write_text(to_dot(obj).to_string())
    return p


def write_svg(obj: Mission | MissionTree, path: str | Path) -> Path:
    """Write the tree as SVG (needs Graphviz's ``dot``). Raises DisplayError."""
    dot = shutil.which("dot")
    if dot is None:
        raise DisplayError("cannot write SVG: Graphviz 'dot' is not installed (apt-get install graphviz), "
                           "or write a .dot file with --dot instead")
    p = Path(path)
    graph = to_dot(obj)
    try:
        data = graph.create(prog=dot, format="svg")
    except (OSError, AssertionError) as e:
        raise DisplayError(f"cannot write SVG: Graphviz 'dot' failed: {e}") from None
    p.write_bytes(data)
    return p
