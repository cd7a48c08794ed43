"""Backends describe themselves (:class:`mmexec.drivers.backendspec.BackendSpec`); the
registry (:mod:`mmexec.executive.backends`) is the only module of the executive that
names them. Checked over the source tree by AST, without importing: no module under
executive/ other than the registry compares a value with a backend's name (``==``,
``!=``, ``in`` / ``not in`` a literal, ``match``/``case``, ``startswith``/``endswith``) or
reads a config's section or keys a table by a backend's literal name (``cfg["sim"]``,
``cfg.get("sim")``, ``{"sim": ...}``).
Messages and docs may mention a backend; deciding by its name is what the check refuses.
"""

from __future__ import annotations

import ast
from pathlib import Path

from mmexec.executive.backends import names

REPO = Path(__file__).resolve().parents[2]
REGISTRY = REPO / "executive" / "backends.py"


def _names_in(node: ast.AST, backends: set[str]) -> list[str]:
    """The backend names ``node`` spells as a literal: a string constant, or the string
    constants of a tuple, list or set literal."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value in backends:
        return [node.value]
    if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
        return [n for elt in node.elts for n in _names_in(elt, backends)]
    return []


def offences(source: str, backends: set[str], filename: str = "<test>") -> list[str]:
    """``LINE: what`` for each place ``source`` decides by a backend's literal name."""
    out = []
    for node in ast.walk(ast.parse(source, filename=filename)):
        found: list[str] = []
        what = ""
        if isinstance(node, ast.Compare):
            found = [n for side in (node.left, *node.comparators) for n in _names_in(side, backends)]
            what = "compares with"
        elif isinstance(node, ast.MatchValue):
            found, what = _names_in(node.value, backends), "matches"
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
            if node.func.attr in ("startswith", "endswith", "get", "pop", "setdefault") and node.args:
                found, what = _names_in(node.args[0], backends), f"calls {node.func.attr}() with"
        elif isinstance(node, ast.Subscript):
            found, what = _names_in(node.slice, backends), "indexes by"
        elif isinstance(node, ast.Dict):
            found = [n for key in node.keys if key is not None for n in _names_in(key, backends)]
            what = "keys a mapping by"
        if found:
            out.append(f"{node.lineno}: {what} {', '.join(map(repr, found))}")
    return out


def test_no_executive_module_but_the_registry_decides_by_a_backend_name() -> None:
    backends = set(names())
    bad = []
    for path in sorted((REPO / "executive").rglob("*.py")):
        if path == REGISTRY:
            continue
        rel = path.relative_to(REPO)
        bad += [f"{rel}:{line}" for line in offences(path.read_text(), backends, str(rel))]
    assert bad == [], "\n".join(bad)


def test_the_checker_sees_each_kind_of_decision() -> None:
    backends = {"mock", "sim", "robot"}
    assert offences('if loaded.backend == "sim":\n    pass\n', backends) == ["1: compares with 'sim'"]
    assert offences('ok = "robot" != cfg.backend\n', backends) == ["1: compares with 'robot'"]
    assert offences('ok = b in ("sim", "mock")\n', backends) == ["1: compares with 'sim', 'mock'"]
    assert offences('match b:\n    case "mock":\n        pass\n', backends) == ["2: matches 'mock'"]
    assert offences('ok = b.startswith("sim")\n', backends) == ["1: calls startswith() with 'sim'"]
    assert offences('world = cfg.get("sim") or {}\n', backends) == ["1: calls get() with 'sim'"]
    assert offences('section = cfg["robot"]\n', backends) == ["1: indexes by 'robot'"]
    assert offences('OFF = {"sim": {"faults": None}}\n', backends) == ["1: keys a mapping by 'sim'"]
    # mentioning a backend in a message or a comment decides nothing
    assert offences('raise ValueError("use a sim config")  # sim only\n', backends) == []
    assert offences('ok = b == spec.name\n', backends) == []
