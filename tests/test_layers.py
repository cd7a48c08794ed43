"""The import rule of docs/architecture.md, checked over the source tree (AST, no import):

    executive -> skills -> capability interfaces <- drivers, sim

* ``config`` (safe loading, shared file helpers) imports nothing else of mmexec;
* the capability contract (``drivers.interfaces``, the robot descriptions of
  ``drivers.descriptions``, the map formats of ``drivers.maps`` and what a backend
  declares about itself, ``drivers.backendspec``) imports only ``config`` and itself;
* ``drivers`` and ``sim`` never import ``skills`` or ``executive``;
* ``skills`` never import ``executive``, ``sim`` or a device package (any ``drivers.X``
  outside the contract); the one exception is the skill test kit's pytest plugin, which
  builds the mock robot its fixtures hand to skills (``skills.testing.pytest_plugin`` ->
  ``drivers.mock``);
* nothing under ``skills/`` imports pybullet at module level (a skill module must load
  without the simulator's engine; the planning scene imports it when first used).

Function-local imports count like any other: an edge hidden in a function is still an
edge. The test lists every offending ``file:line`` at once.
"""

from __future__ import annotations

import ast
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
FOLDERS = ("executive", "skills", "drivers", "sim", "config", "trees")
CONTRACT = ("drivers.interfaces", "drivers.descriptions", "drivers.maps", "drivers.geometry",
            "drivers.backendspec")
#: (importer prefix, imported prefix) pairs allowed against the rules above, with the reason
ALLOWED = {("skills.testing.pytest_plugin", "drivers.mock"): "the test kit's fixtures build the mock robot"}


def _module(path: Path) -> str:
    rel = path.relative_to(REPO).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _imports(path: Path) -> list[tuple[int, str, bool]]:
    """(line, imported mmexec module without the 'mmexec.' prefix, at module level)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    top = {id(n) for n in tree.body}
    # statements inside a module-level `if`/`try` are module level too
    for n in tree.body:
        if isinstance(n, (ast.If, ast.Try)):
            top.update(id(c) for c in ast.walk(n))
    out = []
    for node in ast.walk(tree):
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
        for name in names:
            if name == "mmexec" or name.startswith("mmexec."):
                out.append((node.lineno, name.removeprefix("mmexec").lstrip("."), id(node) in top))
            elif name.split(".")[0] == "pybullet":
                out.append((node.lineno, "<pybullet>", id(node) in top))
    return out


def _layer(mod: str) -> str:
    if any(mod == c or mod.startswith(c + ".") for c in CONTRACT):
        return "contract"
    return mod.split(".")[0]


def _violation(importer: str, imported: str, top_level: bool) -> str | None:
    src, dst = _layer(importer), _layer(imported)
    for a, b in ALLOWED:
        if importer.startswith(a) and imported.startswith(b):
            return None
    if imported == "<pybullet>":
        return "skills import pybullet at module level" if src == "skills" and top_level else None
    if not imported:  # `import mmexec`
        return None
    if src == "config" and dst != "config":
        return "config imports only config"
    if src == "contract" and dst not in ("contract", "config"):
        return "the capability contract imports only itself and config"
    if src in ("drivers", "sim") and dst in ("skills", "executive"):
        return f"{src} never imports {dst}"
    if src == "skills" and dst in ("executive", "sim", "drivers"):
        return f"skills never import {dst if dst != 'drivers' else 'a device package'}"
    if src == "trees" and dst != "trees":
        return "trees hold missions, not code"
    return None


def test_the_import_graph_follows_the_layers() -> None:
    bad = []
    for folder in FOLDERS:
        for path in sorted((REPO / folder).rglob("*.py")):
            importer = _module(path)
            seen: set[int] = set()
            for line, imported, top in _imports(path):
                why = _violation(importer, imported, top)
                if why is not None and line not in seen:  # one line per import statement
                    seen.add(line)
                    bad.append(f"{path.relative_to(REPO)}:{line}: imports {imported or 'mmexec'}: {why}")
    assert bad == [], "\n".join(bad)


def test_the_checker_sees_each_kind_of_edge() -> None:
    # the rule itself, on made-up edges (a checker that never fires would pass anything)
    assert _violation("skills.fetch.arm", "sim.models", False)
    assert _violation("skills.manipulation.kinematics", "drivers.ur.model", True)
    assert _violation("drivers.robot", "skills.navigation.grid", False)
    assert _violation("sim.backend", "executive.config", True)
    assert _violation("drivers.interfaces", "drivers.kobuki.codec", True)
    assert _violation("config.yamlload", "drivers.interfaces", True)
    assert _violation("skills.manipulation.scene", "<pybullet>", True)
    assert _violation("skills.manipulation.scene", "<pybullet>", False) is None
    assert _violation("skills.fetch.arm", "drivers.interfaces", True) is None
    assert _violation("executive.cli", "sim.backend", False) is None
    assert _violation("skills.testing.pytest_plugin", "drivers.mock.robot", False) is None
    assert _violation("skills.testing", "drivers.mock", True)
