"""Display: text tree, dot export, and a clean error when Graphviz is missing."""

from __future__ import annotations

import shutil

import pytest
from test_nodes_support import Harness

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


@pytest.fixture
def h(tmp_path):
    return Harness(tmp_path)


def test_render_text_of_mission_and_ticked_tree(h):
    m = h.load(MISSION)
    text = display.render_text(m)
    assert text.splitlines() == ["{-} shown", "    --> first", "    [o] fallback", "        --> fail", "        --> hold"]
    t = m.instantiate(h.ctx, {})
    t.tick()
    live = display.render_text(t)
    assert "first [✓]" in live and "fail [✕]" in live and "hold [*]" in live


def test_write_dot(h, tmp_path):
    out = display.write_dot(h.load(MISSION), tmp_path / "t.dot")
    text = out.read_text()
    assert text.startswith("digraph") and "first" in text and "fallback" in text and "->" in text


def test_write_svg_without_graphviz_is_a_one_line_error(h, tmp_path, monkeypatch):
    monkeypatch.setattr(shutil, "which", lambda name: None)
    with pytest.raises(display.DisplayError) as ei:
        display.write_svg(h.load(MISSION), tmp_path / "t.svg")
    assert "Graphviz 'dot' is not installed" in str(ei.value) and "\n" not in str(ei.value)
    assert not (tmp_path / "t.svg").exists()
