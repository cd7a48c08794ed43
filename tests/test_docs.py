"""The documentation agrees with the repository: every path a doc names exists, the
mission examples of docs/missions.md compile, its Runtime API example runs, the README
lists every shipped config, and nothing points at documents outside the repository (a
public clone has no ``../shared``). Cheap checks, so the docs do not rot again."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

from mmexec.config.yamlload import load_yaml_text

ROOT = Path(__file__).resolve().parents[1]
DOCS = sorted([ROOT / "README.md", ROOT / "BENCHMARKS.md", *(ROOT / "docs").rglob("*.md")])
#: top-level folders of the repository a doc may name paths in
TOP = ("trees", "config", "docs", "sim", "skills", "executive", "drivers", "tests", "benchmarks")
#: a repository path
PATH = re.compile(rf"(?<![\w./<-])((?:{'|'.join(TOP)})/[\w./*-]*[\w*])")
#: a sample message (``FILE:LINE:COL: ...``): the files it names are examples
SAMPLE = re.compile(r"[\w./-]+\.\w+:\d+:\d+: ")
#: a relative markdown link target
LINK = re.compile(r"\]\((?!https?://|#|mailto:)([^)#\s]+)")
FENCE = re.compile(r"^```(\w*)\s*$")


def _doc_lines(doc: Path) -> list[tuple[int, str, str | None]]:
    """(line number, text, fence language or None outside a fence)."""
    out: list[tuple[int, str, str | None]] = []
    lang: str | None = None
    for i, line in enumerate(doc.read_text().splitlines(), 1):
        m = FENCE.match(line.strip())
        if m:
            lang = None if lang is not None else m.group(1)
            continue
        out.append((i, line, lang))
    return out


def _exists(path: str, *folders: Path) -> bool:
    return any(any(f.glob(path)) if "*" in path else (f / path).exists() for f in folders)


def _missing_paths(doc: Path) -> list[str]:
    """``DOC:LINE: PATH`` for each repository path or relative link in ``doc`` that does
    not exist (a path may also be relative to the doc's folder, as its links are)."""
    name = doc.relative_to(ROOT) if doc.is_relative_to(ROOT) else doc.name
    missing = []
    for i, line, lang in _doc_lines(doc):
        if SAMPLE.search(line):
            continue  # a sample error message: its files are examples
        for m in PATH.finditer(line):
            if not _exists(m.group(1), ROOT, doc.parent):
                missing.append(f"{name}:{i}: {m.group(1)}")
        if lang is None:
            missing += [f"{name}:{i}: link {t}" for t in LINK.findall(line) if not (doc.parent / t).exists()]
    return missing


@pytest.mark.parametrize("doc", DOCS, ids=lambda d: str(d.relative_to(ROOT)))
def test_every_repository_path_a_doc_names_exists(doc: Path) -> None:
    assert _missing_paths(doc) == []


def test_the_path_check_finds_a_missing_file(tmp_path: Path) -> None:
    doc = tmp_path / "x.md"
    doc.write_text("See trees/nowhere.yaml and [this](gone.md).\n"
                   "An error looks like `trees/fetch.yaml:12:14: unknown skill in config/example.yaml`.\n"
                   "```\nmmexec validate config/typo.yaml\n```\n")
    assert [ln.split(": ", 1)[1] for ln in _missing_paths(doc)] == [
        "trees/nowhere.yaml", "link gone.md", "config/typo.yaml"]


def _tracked_text_files() -> list[Path]:
    if not (ROOT / ".git").exists() or shutil.which("git") is None:
        pytest.skip("not a git checkout: the tracked files are unknown")
    names = subprocess.run(["git", "ls-files", "*.py", "*.md", "*.yaml", "Makefile"], cwd=ROOT,
                           capture_output=True, text=True, check=True).stdout.split()
    return [ROOT / n for n in names if (ROOT / n).is_file()]


#: names of documents that live outside the repository
OUTSIDE = re.compile(r"hardware-protocols\.md|library-notes\.md|shared/docs|/work/shared|(?<![\w/.-])robots\.md")


def test_nothing_points_at_documents_outside_the_repository() -> None:
    me = Path(__file__).resolve()
    hits = []
    for f in _tracked_text_files():
        if f.resolve() == me:
            continue
        for i, line in enumerate(f.read_text(errors="replace").splitlines(), 1):
            if OUTSIDE.search(line) and not (f.parent == ROOT / "docs" and "](robots.md)" in line):
                hits.append(f"{f.relative_to(ROOT)}:{i}: {line.strip()[:80]}")
    assert hits == [], "point these at docs/robots.md or docs/protocols.md:\n" + "\n".join(hits)


def test_the_readme_lists_every_shipped_config() -> None:
    readme = (ROOT / "README.md").read_text()
    configs = sorted(p.relative_to(ROOT).as_posix() for p in (ROOT / "config").glob("*.yaml"))
    assert configs and [c for c in configs if f"`{c}`" not in readme] == []


# --------------------------------------------------------------------------- docs/missions.md

MISSIONS = ROOT / "docs" / "missions.md"
#: what the node examples may use: a request field, two parameters
WRAPPER = ("mission: doc_example\nparams:\n  home: {type: str, default: home}\n"
           "  approach_distance: {type: float, default: 0.45}\nrequests:\n  item: {type: int}\ntree:\n")


def _blocks(doc: Path, lang: str) -> list[tuple[int, str]]:
    text = doc.read_text()
    return [(text[: m.start()].count("\n") + 2, m.group(1))
            for m in re.finditer(rf"^```{lang}\n(.*?)^```", text, re.DOTALL | re.MULTILINE)]


def _node_examples() -> list[tuple[int, str]]:
    from mmexec.executive.schema import NODE_TYPES

    out = []
    for line, block in _blocks(MISSIONS, "yaml"):
        data = load_yaml_text(block, f"docs/missions.md:{line}")
        if isinstance(data, dict) and set(data) & set(NODE_TYPES):
            out.append((line, block))
    return out


def test_every_node_example_of_missions_md_compiles(tmp_path: Path) -> None:
    """Each node example, put under ``tree:`` of a mission file in a folder holding the
    example subtrees (trees/examples/subtrees), compiles with the built-in skills."""
    import mmexec.skills.fetch
    import mmexec.skills.primitives  # noqa: F401 - registers the skills the examples use
    from mmexec.config.yamlload import InputError
    from mmexec.executive.compiler import load_mission

    shutil.copytree(ROOT / "trees" / "examples" / "subtrees", tmp_path / "subtrees")
    examples = _node_examples()
    assert len(examples) >= 12, examples  # the node reference has an example per node type
    problems = []
    for line, block in examples:
        f = tmp_path / f"example_{line}.yaml"
        f.write_text(WRAPPER + "".join(f"  {ln}\n" for ln in block.splitlines()))
        try:
            load_mission(f)
        except InputError as e:
            problems.append(f"docs/missions.md:{line}: {e}")
    assert problems == []


def test_the_runtime_api_example_runs(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    section = MISSIONS.read_text().split("## Runtime API", 1)[1]
    code = re.search(r"```python\n(.*?)```", section, re.DOTALL)
    assert code is not None
    monkeypatch.chdir(ROOT)  # the example names repository paths
    scope: dict[str, object] = {}
    exec(compile(code.group(1), "docs/missions.md (Runtime API)", "exec"), scope)  # noqa: S102 - our own doc
    from py_trees.common import Status

    tree = scope["tree"]
    assert tree.root.status is Status.SUCCESS  # type: ignore[attr-defined]
    assert "demo_fetch: RUNNING -> SUCCESS" in capsys.readouterr().out
