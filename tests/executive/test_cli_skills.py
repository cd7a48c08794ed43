"""``mmexec skills``: the catalogue of built-in and config skills; ``validate`` and
``show`` without ``--config`` say to pass one when a skill is unknown."""

from __future__ import annotations

import re
from pathlib import Path

from mmexec.executive.catalog import describe_skill
from mmexec.skills.base import REGISTRY, Output, Param, SkillSpec

USER_SKILL = '''\
from mmexec.skills.base import Output, Param, skill


@skill("present_{tag}", params=[Param("pose", str, required=True, doc="named pose"),
                              Param("hold", float, unit="s", default=1.5, doc="how long to hold")],
       outputs=[Output("holding", bool)], needs=("arm", "gripper"))
def present(ctx, pose, hold=1.5):
    """Show the held item at a named pose. More text that the catalogue leaves out."""
    yield
    return {{"holding": True}}
'''

MISSION = """\
mission: show_it
tree:
  skill: present_{tag}
  params: {{pose: ready}}
"""


def user_files(tmp_path: Path, tag: str) -> tuple[Path, Path]:
    """A skill module next to a config that names it (``skills.paths: [.]``), and a
    mission using its skill. ``tag`` keeps module and skill names unique per test."""
    (tmp_path / f"lab_{tag}.py").write_text(USER_SKILL.format(tag=tag))
    config = tmp_path / "config.yaml"
    config.write_text(f"backend: mock\nskills:\n  paths: [.]\n  modules: [lab_{tag}]\n")
    mission = tmp_path / "mission.yaml"
    mission.write_text(MISSION.format(tag=tag))
    return config, mission


def row(out: str, skill: str, param: str) -> list[str]:
    """The cells of ``param``'s row in ``skill``'s entry (split on two or more spaces)."""
    entry = out.split(f"\n\n{skill}  (", 1)[1].split("\n\n", 1)[0]
    line = next(ln for ln in entry.splitlines() if ln.strip().startswith(param + " "))
    return re.split(r"\s{2,}", line.strip())


def test_skills_lists_every_builtin_skill_with_its_declaration(run_cli) -> None:
    from mmexec.executive.config import load_skill_modules

    load_skill_modules(None)
    res = run_cli("skills")
    assert res.rc == 0, res.err
    builtin = [n for n in REGISTRY.names() if REGISTRY.get(n).fn.__module__.startswith("mmexec.")]
    assert {"drive_to", "move_arm", "close_gripper", "navigate", "pick", "search", "report"} <= set(builtin)
    for name in builtin:
        assert f"\n\n{name}  (built-in: " in res.out, name
    assert res.out.splitlines()[0].startswith(f"{len(REGISTRY.names())} skills: {len(builtin)} built-in")
    assert "pass --config CONFIG" in res.out.splitlines()[0]
    assert "drive_to  (built-in: mmexec.skills.primitives; needs base)" in res.out
    assert row(res.out, "drive_to", "x") == ["x", "float", "m", "-", "goal x in map"]
    assert row(res.out, "drive_to", "max_angular") == ["max_angular", "float", "rad/s", "1.0"]
    assert row(res.out, "wait", "seconds") == ["seconds", "float", "s", "required", "clock time to wait"]
    assert row(res.out, "close_gripper", "expect")[:4] == ["expect", "str", "-", "any"]
    assert row(res.out, "close_gripper", "expect")[4].endswith("one of: any, object, empty")
    assert "pick  (built-in: mmexec.skills.fetch.arm; needs arm, gripper)" in res.out
    assert "  outputs: holding (bool)" in res.out.split("\n\nclose_gripper  (", 1)[1]


def test_skills_with_config_adds_the_config_modules_skills(run_cli, tmp_path: Path) -> None:
    config, _ = user_files(tmp_path, "cat1")
    res = run_cli("skills", "--config", config)
    assert res.rc == 0, res.err
    assert f"from the modules of {config}" in res.out.splitlines()[0]
    assert "present_cat1  (from: lab_cat1; needs arm, gripper)" in res.out
    assert "  Show the held item at a named pose.\n" in res.out
    assert row(res.out, "present_cat1", "pose") == ["pose", "str", "-", "required", "named pose"]
    assert row(res.out, "present_cat1", "hold") == ["hold", "float", "s", "1.5", "how long to hold"]
    res = run_cli("skills", "present_cat1", "wait", "--config", config)
    assert res.rc == 0 and res.out.splitlines()[0].startswith("2 skills: 1 built-in, 1 from the modules of")
    assert "\n\npresent_cat1  (" in res.out and "\n\nwait  (" in res.out and "drive_to" not in res.out


def test_skills_unknown_name_or_bad_config_is_one_line(run_cli, tmp_path: Path) -> None:
    res = run_cli("skills", "drive_too")
    assert res.rc == 2
    assert res.err.strip() == ("mmexec skills #1: unknown skill 'drive_too'; did you mean 'drive_to'?; a skill "
                               "from your own modules needs --config CONFIG (its skills.modules are loaded first)")
    bad = tmp_path / "bad.yaml"
    bad.write_text("backend: mock\nskills: {modules: [no_such_module_cat]}\n")
    res = run_cli("skills", "--config", bad)
    assert res.rc == 2 and res.err.strip().startswith(f"{bad}:2:20: skills.modules[0]: cannot import")


def test_validate_without_config_says_to_pass_one_for_an_unknown_skill(run_cli, tmp_path: Path) -> None:
    config, mission = user_files(tmp_path, "cat2")
    res = run_cli("validate", mission)
    assert res.rc == 2
    (line,) = res.err.strip().splitlines()
    assert line.startswith(f"{mission}:3:10: unknown skill 'present_cat2'")
    assert line.endswith("; a skill from your own modules needs --config CONFIG (its skills.modules are loaded first)")
    res = run_cli("show", mission)
    assert res.rc == 2 and "needs --config CONFIG" in res.err
    res = run_cli("validate", mission, "--config", config)
    assert res.rc == 0, res.err
    mission.write_text(MISSION.format(tag="nowhere"))
    res = run_cli("validate", mission, "--config", config)  # with a config the hint would mislead
    assert res.rc == 2 and "unknown skill 'present_nowhere'" in res.err and "--config" not in res.err


def test_describe_skill_without_params_or_doc() -> None:
    def fn(ctx):  # pragma: no cover - never run
        yield

    fn.__module__ = "mmexec.skills.example"
    spec = SkillSpec("bare", fn, outputs=(Output("n", int),))
    assert describe_skill(spec) == ("bare  (built-in: mmexec.skills.example; needs nothing)\n"
                                    "  parameters: none\n  outputs: n (int)")
    spec = SkillSpec("flag", fn, params=(Param("on", bool, default=False),), doc="Set it.\n\nDetails.")
    assert describe_skill(spec).splitlines()[1:3] == ["  Set it.", "  parameter  type  unit  default  description"]
    assert describe_skill(spec).splitlines()[3] == "  on         bool  -     false"
