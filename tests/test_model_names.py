"""Nothing under ``skills/`` or ``sim/`` decides by a robot model's name (docs: design
brief, "Robot descriptions"): facts come from the active robot's description
(``Robot.description``, :mod:`mmexec.drivers.descriptions`), so adding a robot means
adding one description module and one config.

Checked over the source tree (AST, no import): a comparison (``==``, ``!=``, ``in``,
``not in``, ``is``) with a string literal naming a known model, a ``match`` case on one,
and ``startswith`` / ``endswith`` with a literal that begins or ends a known name. Known
names: every registered description, every arm chain, the UR models, and each
``_``-separated part of them (``locobot``, ``wx250s``, ``ur5e``, ...). Looking a
description up by name (``get("ur5e_robotiq")``) is not a decision and is allowed. The
test lists every offending ``file:line`` at once.
"""

from __future__ import annotations

import ast
from pathlib import Path

from mmexec.drivers.descriptions import DESCRIPTIONS
from mmexec.drivers.descriptions import ur as ur_arm

REPO = Path(__file__).resolve().parents[1]
FOLDERS = ("skills", "sim")


def _known_names() -> frozenset[str]:
    names = set(DESCRIPTIONS) | set(ur_arm.MODELS)
    names |= {d.arm.name for d in DESCRIPTIONS.values() if d.arm is not None}
    parts = {part for n in names for part in n.split("_") if len(part) >= 3}
    return frozenset(n.lower() for n in names | parts)


KNOWN = _known_names()


def _strings(node: ast.AST) -> list[str]:
    """The string literals of ``node``: a constant, or the items of a literal tuple/list/set."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return [node.value]
    if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
        return [s for elt in node.elts for s in _strings(elt)]
    return []


def _affix_of_a_name(s: str, attr: str) -> bool:
    s = s.lower()
    if len(s) < 3:
        return False
    return any(n.startswith(s) if attr == "startswith" else n.endswith(s) for n in KNOWN)


def offences(source: str, filename: str = "<source>") -> list[tuple[int, str]]:
    """(line, what) of each decision on a model name in ``source``."""
    out: list[tuple[int, str]] = []
    for node in ast.walk(ast.parse(source, filename=filename)):
        if isinstance(node, ast.Compare):
            for s in (s for operand in (node.left, *node.comparators) for s in _strings(operand)):
                if s.lower() in KNOWN:
                    out.append((node.lineno, f"compares with the model name {s!r}"))
        elif isinstance(node, ast.match_case):
            for sub in ast.walk(node.pattern):
                if isinstance(sub, ast.MatchValue):
                    out.extend((sub.lineno, f"matches the model name {s!r}")
                               for s in _strings(sub.value) if s.lower() in KNOWN)
        elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
              and node.func.attr in ("startswith", "endswith")):
            for s in (s for arg in node.args for s in _strings(arg)):
                if _affix_of_a_name(s, node.func.attr):
                    out.append((node.lineno, f"{node.func.attr}({s!r}) tests a model name"))
    return out


def test_no_skill_or_sim_module_decides_by_a_model_name() -> None:
    bad = []
    for folder in FOLDERS:
        for path in sorted((REPO / folder).rglob("*.py")):
            for line, what in offences(path.read_text(), str(path)):
                bad.append(f"{path.relative_to(REPO)}:{line}: {what}")
    assert bad == [], "\n".join(bad)


def test_the_checker_sees_each_kind_of_decision() -> None:
    # the rule itself, on made-up code (a checker that never fires would pass anything)
    assert offences('if cfg.robot == "locobot_wx250s":\n    pass\n') == [
        (1, "compares with the model name 'locobot_wx250s'")]
    assert offences('x = a if "ur5e_robotiq" != name else b\n')
    assert offences('ok = name in ("ur5e", "ur3e")\n')
    assert offences('if name.startswith("locobot"):\n    pass\n')
    assert offences('if name.endswith("_robotiq"):\n    pass\n')
    assert offences('if name.startswith(("loco", "ur")):\n    pass\n')  # "loco" begins a name
    assert offences('match name:\n    case "wx250s":\n        pass\n')
    assert offences('ok = model is "ur3e"\n')
    # what is allowed: looking a description up, other strings, a bare short prefix
    assert offences('d = get("ur5e_robotiq")\n') == []
    assert offences('ok = reason.startswith("start in collision")\n') == []
    assert offences('ok = a.startswith("robot/") and mode == "interbotix"\n') == []
    assert offences('ok = s.startswith("ur")\n') == []
