"""Random and mutated mission files never raise anything but InputError from load_mission."""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_malformed import corpus_registry

from mmexec.config.yamlload import InputError
from mmexec.executive.compiler import load_mission

HERE = Path(__file__).parent
SEEDS = [p.read_bytes() for p in sorted((HERE.parents[1] / "trees" / "examples").glob("*.yaml"))]
SEEDS += [p.read_bytes() for p in sorted((HERE / "malformed").glob("*.yaml"))[:10]]
SEEDS.append(b"""tree:
  sequence:
    - recovery: {action: {skill: succeed}, recovery: {skill: fail}, max_recoveries: 1}
    - parallel: [{wait: 1}, {condition: x, op: exists}]
    - retry: {timeout: {skill: hold}, seconds: 2}
      attempts: 2
    - skill: pick
      params: {marker: "{request.item}"}
      outputs: {}
requests:
  item: int
""")
TOKENS = [b"sequence:", b"fallback:", b"parallel:", b"retry:", b"timeout:", b"repeat:", b"invert:",
          b"condition:", b"wait:", b"skill:", b"include:", b"recovery:", b"params:", b"outputs:", b"tree:",
          b"- ", b"  ", b"\n", b"{", b"}", b"[", b"]", b"&a ", b"*a", b"\"{x}\"", b"{request.item}", b"!!str",
          b"!!python/object:x", b"\xff", b"\x00", b"---\n", b"include: ../malformed/unknown_skill.yaml",
          b"include: m.yaml", b"max_recoveries: -1", b"policy: 7", b": ", b"1e999", b"~", b"<<: *a",
          b"\"{x:.2f}\"", b"{request.item:03d}", b":.2q", b":99999999", b"{x:}",
          b"foreach: ", b"as: x", b"do: ", b"if: ", b"then: ", b"else: ", b"foreach: \"{request.item}\""]
REG = corpus_registry()
TMP = Path(tempfile.mkdtemp(prefix="mmexec-fuzz-"))


@pytest.fixture(scope="module", autouse=True)
def _remove_tmp():
    """Hypothesis runs many examples per test, so the mission file lives in one module
    folder rather than a function-scoped tmp_path; remove it when the module is done."""
    yield
    shutil.rmtree(TMP, ignore_errors=True)


def check(data: bytes) -> None:
    p = TMP / "m.yaml"
    p.write_bytes(data)
    try:
        load_mission(p, REG)
    except InputError as e:
        assert str(e).strip(), "empty error message"


@st.composite
def mutated(draw: st.DrawFn) -> bytes:
    data = bytearray(draw(st.sampled_from(SEEDS)))
    for _ in range(draw(st.integers(1, 4))):
        op = draw(st.integers(0, 3))
        pos = draw(st.integers(0, len(data)))
        if op == 0:
            data[pos:pos] = draw(st.sampled_from(TOKENS))
        elif op == 1 and data:
            end = min(len(data), pos + draw(st.integers(1, 40)))
            del data[pos:end]
        elif op == 2:
            data[pos:pos] = draw(st.binary(max_size=8))
        else:
            a = draw(st.integers(0, len(data)))
            data[pos:pos] = data[min(a, pos):max(a, pos)][:200]
    return bytes(data)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(mutated())
def test_mutated_missions_only_raise_input_error(data):
    check(data)


@settings(max_examples=50, deadline=None)
@given(st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=True) | st.sampled_from(
        ["sequence", "skill", "succeed", "tree", "{x}", "{request.item}", "pick", "exists", "=="]),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(
        st.sampled_from(["tree", "sequence", "fallback", "skill", "params", "name", "recovery", "action",
                         "retry", "attempts", "condition", "op", "value", "wait", "include", "requests", "item",
                         "foreach", "as", "do", "if", "then", "else"]),
        inner, max_size=4),
    max_leaves=20))
def test_random_structures_only_raise_input_error(value):
    import json

    check(json.dumps({"tree": value}).encode())
