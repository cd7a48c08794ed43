"""Compiler: includes with parameters, requests and params, identity, example missions."""

from __future__ import annotations

from pathlib import Path

import pytest
from py_trees.common import Status

import mmexec.skills.primitives  # noqa: F401  (registers the primitive skills the examples use)
from mmexec.config.yamlload import InputError
from mmexec.executive.compiler import MAX_INCLUDE_DEPTH, load_mission
from mmexec.skills.base import REGISTRY

EXAMPLES = sorted((Path(__file__).resolve().parents[2] / "trees" / "examples").glob("*.yaml"))


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.stem)
def test_examples_validate_and_build(path):
    m = load_mission(path, REGISTRY)
    tree = m.display_tree()
    assert len(tree.nodes()) == m.node_count
    assert tree.root.status is Status.INVALID


def test_examples_cover_every_node_type():
    text = "\n".join(p.read_text() for p in EXAMPLES) + (EXAMPLES[0].parent / "subtrees" / "park_arm.yaml").read_text()
    for kind in ("sequence", "fallback", "parallel", "retry", "timeout", "repeat", "invert", "force_success",
                 "force_failure", "condition", "wait", "skill", "include", "recovery"):
        assert f"{kind}:" in text, kind


def test_include_binds_params_and_paths(h):
    h.write("sub/leaf.yaml", """
        params:
          ticks: {type: int, default: 0}
          label: {type: str}
        tree:
          skill: succeed
          name: work
          params: {ticks: "{ticks}", value: "{label}-{request.item}"}
          outputs: {value: out}
    """)
    t = h.tree("""
        params:
          n: {type: int, default: 1}
        requests:
          item: int
        tree:
          sequence:
            - include: sub/leaf.yaml
              params: {ticks: "{n}", label: first}
            - include: sub/leaf.yaml
              name: again
              params: {label: second}
    """, request={"item": "5"}, params={"n": "2"})
    assert h.run(t) == (Status.SUCCESS, 3)
    assert [p for p, e in h.journal if e == "start"] == ["m/leaf/work", "m/again/work"]
    assert t.blackboard()["out"] == "second-5"


def test_include_depth_is_bounded(h):
    for i in range(MAX_INCLUDE_DEPTH + 3):
        h.write(f"d{i}.yaml", f"tree:\n  include: d{i + 1}.yaml\n")
    h.write(f"d{MAX_INCLUDE_DEPTH + 3}.yaml", "tree:\n  skill: succeed\n")
    with pytest.raises(InputError, match=f"includes nest deeper than {MAX_INCLUDE_DEPTH} files"):
        load_mission(h.tmp / "d0.yaml", h.registry)


def test_self_include_is_a_cycle(h):
    p = h.write("self.yaml", "tree:\n  include: self.yaml\n")
    with pytest.raises(InputError) as ei:
        load_mission(p, h.registry)
    assert str(ei.value) == f"{p}:2:12: include cycle: {p} -> {h.tmp / 'self.yaml'}"


def test_validate_request_converts_and_rejects(h):
    m = h.load("""
        requests:
          item: int
          speed: float
          fast: bool
          name: str
          tags: list
        tree:
          skill: succeed
    """)
    ok = m.validate_request({"item": "3", "speed": "0.5", "fast": "yes", "name": "cup", "tags": "[a, b]"})
    assert ok == {"item": 3, "speed": 0.5, "fast": True, "name": "cup", "tags": ["a", "b"]}
    assert m.validate_request({"item": 3, "speed": 1, "fast": False, "name": "x", "tags": []})["speed"] == 1.0
    with pytest.raises(ValueError, match="request field 'item': expected int, got 'three'"):
        m.validate_request({"item": "three", "speed": 1, "fast": True, "name": "", "tags": []})
    with pytest.raises(ValueError, match="unknown field 'iten'; did you mean 'item'"):
        m.validate_request({"iten": 1})
    with pytest.raises(ValueError, match="missing field 'speed'"):
        m.validate_request({"item": 1})


def test_params_override_and_errors(h):
    m = h.load("""
        params:
          n: {type: int, default: 1}
          must: {type: str}
        tree:
          skill: succeed
          params: {value: "{must}", ticks: "{n}"}
    """)
    assert m.resolve_params({"must": "x"}) == {"n": 1, "must": "x"}
    with pytest.raises(ValueError, match="missing required parameter 'must'"):
        m.instantiate(h.ctx, {}, {})
    with pytest.raises(ValueError, match="unknown parameter 'nn'; did you mean 'n'"):
        m.instantiate(h.ctx, {}, {"nn": 2, "must": "x"})
    t = m.instantiate(h.ctx, {}, {"must": "hello", "n": 3})
    assert h.run(t) == (Status.SUCCESS, 4)
    assert h.events[0][1]["node"] == "m"


def test_identity_files_and_hash(h):
    h.write("sub.yaml", "tree:\n  skill: succeed\n")
    p = h.write("top.yaml", "mission: top\ntree:\n  include: sub.yaml\n")
    m = load_mission(p, h.registry)
    assert m.name == "top"
    assert [f.name for f in m.files] == ["top.yaml", "sub.yaml"]
    before = m.sha256
    h.write("sub.yaml", "tree:\n  skill: fail\n")
    assert load_mission(p, h.registry).sha256 != before


def test_each_instantiate_is_a_fresh_tree(h):
    m = h.load("tree:\n  skill: succeed\n  outputs: {value: v}\n  params: {value: 1}\n")
    a, b = m.instantiate(h.ctx, {}), m.instantiate(h.ctx, {})
    a.tick()
    assert a.blackboard() == {"v": 1} and b.blackboard() == {}
    assert a.root is not b.root


def test_load_builds_no_trees_and_reads_only_files(h, monkeypatch):
    from mmexec.executive.nodes import MissionNode

    created = []
    orig = MissionNode._mn_init

    def spy(self, rt, path, name, children):
        created.append(path)
        orig(self, rt, path, name, children)

    monkeypatch.setattr(MissionNode, "_mn_init", spy)
    m = h.load("tree:\n  sequence: [{skill: succeed}, {wait: 1}]\n")
    assert created == []
    m.instantiate(h.ctx, {})
    assert sorted(created) == ["m", "m/succeed", "m/wait"]


def test_large_generated_mission_compiles(h):
    leaves = "\n".join(f"    - skill: succeed\n      name: s{i}" for i in range(600))
    m = h.load(f"tree:\n  sequence:\n{leaves}\n")
    assert m.node_count == 601
    t = m.instantiate(h.ctx, {})
    assert t.tick() is Status.SUCCESS


def test_node_count_expands_each_include_where_it_is_used(h):
    h.write("leaf.yaml", "tree: {sequence: [{skill: succeed}, {skill: succeed}]}\n")
    h.write("pair.yaml", "tree:\n  sequence:\n    - include: leaf.yaml\n    - include: leaf.yaml\n")
    m = h.load("tree:\n  fallback:\n    - include: pair.yaml\n    - include: pair.yaml\n    - skill: fail\n")
    # leaf: 3; pair: 1 + 2 * (include + 3) = 9; root: 1 + 2 * (include + 9) + 1 = 22
    assert m.node_count == 22
    assert len(m.instantiate(h.ctx, {}).nodes()) == 22


def test_include_bomb_is_refused_by_node_count_before_building(h):
    h.write("f0.yaml", "tree: {skill: succeed}\n")
    for k in range(1, 15):
        h.write(f"f{k}.yaml", f"tree:\n  sequence:\n    - include: f{k - 1}.yaml\n    - include: f{k - 1}.yaml\n")
    with pytest.raises(InputError) as ei:
        h.load("tree: {include: f14.yaml}\n")
    # f0 has 1 node, f_k = 1 + 2 * (1 + f_(k-1)) = 4 * 2**k - 3; the root include adds one
    assert str(ei.value) == f"{h.tmp / 'm.yaml'}:1:8: mission has {4 * 2**14 - 2} nodes once includes are expanded, more than 50000"
