"""The skill catalogue: what ``mmexec skills`` prints (docs/cli.md).

For each registered skill: its name, where it comes from (``built-in`` for mmexec's own
skill modules, else the user module that defined it), the capabilities it needs, the
first sentence of its doc, then one row per parameter (name, type, unit, default or
``required``, description with the allowed values) and its outputs::

    drive_to  (built-in: mmexec.skills.primitives; needs base)
      Drive the base straight to a pose in ``map`` (turn, drive, turn), with no obstacle avoidance.
      parameter        type   unit   default  description
      x                float  m      -        goal x in map
      ...
      outputs: pose (list)

``-`` as a default means the parameter is optional and has no default (the skill
decides, usually from the robot profile).
"""

from __future__ import annotations

from collections.abc import Iterable

from mmexec.skills.base import Param, SkillRegistry, SkillSpec

__all__ = ["BUILTIN_PREFIX", "catalogue", "describe_skill", "is_builtin"]

#: Skills whose function lives under this package are mmexec's own.
BUILTIN_PREFIX = "mmexec."

_HEAD = ("parameter", "type", "unit", "default", "description")


def is_builtin(spec: SkillSpec) -> bool:
    """Whether ``spec`` is one of mmexec's own skills (not from a config's module)."""
    return spec.fn.__module__.startswith(BUILTIN_PREFIX)


def _summary(doc: str) -> str:
    """The first sentence of the first paragraph of ``doc``, on one line."""
    para = " ".join(doc.strip().split("\n\n", 1)[0].split())
    end = para.find(". ")
    return para if end < 0 else para[: end + 1]


def _default(p: Param) -> str:
    if p.required:
        return "required"
    if p.default is None:
        return "-"
    if isinstance(p.default, bool):
        return "true" if p.default else "false"
    return repr(p.default) if isinstance(p.default, float) else str(p.default)


def _row(p: Param) -> tuple[str, ...]:
    doc = p.doc
    if p.choices:
        doc = (doc + "; " if doc else "") + "one of: " + ", ".join(str(c) for c in p.choices)
    return (p.name, p.type.__name__, p.unit or "-", _default(p), doc)


def describe_skill(spec: SkillSpec) -> str:
    """The catalogue entry of one skill (several lines, no trailing newline)."""
    origin = "built-in" if is_builtin(spec) else "from"
    needs = ", ".join(spec.needs) or "nothing"
    lines = [f"{spec.name}  ({origin}: {spec.fn.__module__}; needs {needs})"]
    summary = _summary(spec.doc)
    if summary:
        lines.append(f"  {summary}")
    if spec.params:
        rows = [_HEAD, *(_row(p) for p in spec.params)]
        widths = [max(len(r[i]) for r in rows) for i in range(len(_HEAD) - 1)]
        for r in rows:
            cells = [c.ljust(w) for c, w in zip(r[:-1], widths)]
            lines.append(("  " + "  ".join(cells) + "  " + r[-1]).rstrip())
    else:
        lines.append("  parameters: none")
    outs = ", ".join(f"{o.name} ({getattr(o.type, '__name__', str(o.type))})" for o in spec.outputs)
    lines.append(f"  outputs: {outs or 'none'}")
    return "\n".join(lines)


def catalogue(registry: SkillRegistry, *, source: str | None = None, names: Iterable[str] | None = None) -> str:
    """Every skill of ``registry`` (or only ``names``), sorted by name, after a count
    line; ``source`` names the config whose modules were loaded."""
    specs = [s for n in (registry.names() if names is None else sorted(names))
             if (s := registry.get(n)) is not None]
    own = sum(is_builtin(s) for s in specs)
    user = len(specs) - own
    where = f", {user} from the modules of {source}" if source is not None else (
        f", {user} from other modules" if user else "")
    hint = "" if source is not None else " (pass --config CONFIG to add the skills of its skills.modules)"
    head = f"{len(specs)} skill{'' if len(specs) == 1 else 's'}: {own} built-in{where}{hint}"
    return "\n\n".join([head, *(describe_skill(s) for s in specs)])
