"""Render mission trees: py_trees' unicode tree as text, Graphviz dot and SVG files.

``render_text(mission_or_tree)`` accepts a :class:`~mmexec.executive.compiler.Mission`
(rendered from a display-only tree with default parameters) or a
:class:`~mmexec.executive.compiler.MissionTree` (rendered with current statuses).
SVG needs Graphviz's ``dot`` program; without it :func:`write_svg` raises
:class:`DisplayError` with a one-line message saying what to install.
"""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import py_trees

from mmexec.executive.compiler import Mission, MissionTree

__all__ = ["DisplayError", "render_text", "to_dot", "write_dot", "write_svg"]


class DisplayError(OSError):
    """A tree could not be rendered (e.g. Graphviz missing)."""


def _tree(obj: Mission | MissionTree) -> MissionTree:
    if isinstance(obj, Mission):
        return obj.display_tree()
    return obj


def render_text(obj: Mission | MissionTree, show_status: bool | None = None) -> str:
    """py_trees' unicode tree. Statuses are shown for a MissionTree that has been
    ticked (``show_status`` forces either way)."""
    tree = _tree(obj)
    if show_status is None:
        show_status = isinstance(obj, MissionTree) and any(n.status is not py_trees.common.Status.INVALID for n in tree.nodes())
    return py_trees.display.unicode_tree(tree.root, show_status=show_status)


def to_dot(obj: Mission | MissionTree) -> Any:
    """The tree as a ``pydot.Dot`` graph."""
    return py_trees.display.dot_tree(_tree(obj).root)


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
