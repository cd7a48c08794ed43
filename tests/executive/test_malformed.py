"""The malformed-mission corpus: each file's first line says the expected problem."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from test_nodes_support import registry

from mmexec.config.yamlload import InputError
from mmexec.executive.compiler import load_mission
from mmexec.skills.base import Param, SkillSpec

CORPUS = Path(__file__).parent / "malformed"
FILES = sorted(CORPUS.glob("*.yaml"))


def _pick(ctx, marker, approach=0.3, mode="top"):  # pragma: no cover - never run, only declared
    yield
    return {}


def corpus_registry():
    reg = registry()
    reg.register(SkillSpec("pick", _pick, (
        Param("marker", int, required=True),
        Param("approach", float, unit="m", default=0.3),
        Param("mode", str, default="top", choices=("top", "side")),
    )))
    return reg


def test_corpus_is_big_enough():
    assert len(FILES) >= 30


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.stem)
def test_malformed_mission_reports_expected_problem(path):
    first = path.read_text().splitlines()[0]
    m = re.fullmatch(r"# expect: (.*)", first)
    assert m, f"{path.name}: first line must be '# expect: ...'"
    expect = m.group(1)
    with pytest.raises(InputError) as ei:
        load_mission(path, corpus_registry())
    text = str(ei.value)
    if re.match(r"\d+:\d+: ", expect):
        assert f"{path}:{expect}" in text, text
    else:
        assert expect in text, text
    # one problem per line, each located
    for line in text.splitlines():
        assert re.match(r".+:\d+:\d+: \S", line), line


def test_all_problems_reported_at_once(tmp_path):
    p = tmp_path / "many.yaml"
    p.write_text(
        "tree:\n"
        "  sequence:\n"
        "    - skill: pik\n"
        "    - skill: pick\n"
        "      params: {marker: x}\n"
        "    - wiat: 2\n"
        "  memroy: true\n"
    )
    with pytest.raises(InputError) as ei:
        load_mission(p, corpus_registry())
    lines = str(ei.value).splitlines()
    assert [ln.split(": ", 1)[0].rsplit(":", 2)[1:] for ln in lines] == [["3", "14"], ["5", "24"], ["6", "7"], ["7", "3"]]
    assert "did you mean 'pick'" in lines[0] and "did you mean 'wait'" in lines[2]
