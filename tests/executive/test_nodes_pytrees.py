"""Compiled nodes stay usable as py_trees behaviours although the executive builds them
without py_trees' constructors (ids, loggers, parents, visitors, display)."""

from __future__ import annotations

import uuid

import py_trees
import pytest
from py_trees.common import Status

from mmexec.executive import nodes as N

MISSION = """
mission: m
tree:
  sequence:
    - skill: succeed
    - fallback:
        - invert: {skill: succeed}
        - retry: {wait: 0.1}
          attempts: 2
    - parallel: [{skill: succeed, name: a}, {skill: succeed, name: b}]
      policy: one
    - recovery:
        action: {skill: succeed}
        recovery: {skill: succeed}
        max_recoveries: 1
"""


def test_ids_are_unique_stable_uuids_and_parents_are_linked(h):
    t = h.tree(MISSION)
    nodes = t.nodes()
    assert len(nodes) == 13
    ids = [n.id for n in nodes]
    assert all(isinstance(i, uuid.UUID) for i in ids)
    assert len(set(ids)) == len(ids)
    assert [n.id for n in nodes] == ids  # drawn once, then kept
    assert t.root.parent is None
    for n in nodes:
        for c in n.children:
            assert c.parent is n
        assert isinstance(n, py_trees.behaviour.Behaviour)
        assert n.qualified_name == f"{type(n).__qualname__}/{n.name}"
        assert n.status is Status.INVALID and n.blackboards == [] and n.feedback_message == ""
    assert t.root.children[1].children[0].decorated is t.root.children[1].children[0].children[0]
    assert t.root.memory is True and t.root.children[2].policy.__class__.__name__ == "SuccessOnOne"


def test_logger_and_iterator_are_py_trees_objects_made_on_first_use(h):
    t = h.tree(MISSION)
    leaf = t.root.children[0]
    assert "_logger" not in leaf.__dict__ and "_iterator" not in leaf.__dict__
    assert isinstance(leaf.logger, py_trees.logging.Logger)
    assert leaf.logger is leaf.logger
    assert leaf.logger.prefix.startswith("succeed")
    it = leaf.iterator
    assert it is leaf.iterator and hasattr(it, "__next__")


def test_a_node_cannot_get_a_second_parent(h):
    t = h.tree(MISSION)
    leaf = t.root.children[0]
    with pytest.raises(RuntimeError, match=r"m/again: node 'm/succeed' already has a parent \('m'\)"):
        N.Sequence(t.rt, "m/again", "again", [leaf])


def test_py_trees_tick_once_visitors_and_snapshot_work_on_a_compiled_tree(h):
    t = h.tree(MISSION)
    visitor = py_trees.visitors.SnapshotVisitor()
    tree = py_trees.trees.BehaviourTree(t.root)
    tree.add_visitor(visitor)
    tree.tick()
    assert visitor.visited[t.root.id] is Status.RUNNING  # the retry's wait is running
    assert t.root.status is Status.RUNNING
    text = py_trees.display.unicode_tree(t.root, show_status=True, visited=visitor.visited)
    assert "[*]" in text and "wait" in text


def test_dot_export_has_one_graph_node_per_tree_node(h):
    # py_trees' dot export tells same-named nodes apart by their ids
    t = h.tree(MISSION)
    dot = py_trees.display.dot_tree(t.root)
    names = [n.get_name() for n in dot.get_nodes() if n.get_name() not in ("graph", "node", "edge")]
    assert len(names) == len(set(names)) == len(t.nodes()) == 13
    assert len(dot.get_edges()) == 12
    assert names.count("succeed") == 1 and "succeed*" in names and "succeed**" in names
