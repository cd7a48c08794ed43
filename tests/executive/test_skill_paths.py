"""``skills.paths``: skill modules next to the user's config load without PYTHONPATH, for
a run and for campaign trials; the folders stay inside the config's folder tree or its
``roots:``; the campaign reports a user module's problem against the user's config."""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from mmexec.config.yamlload import InputError, load_yaml
from mmexec.executive.config import load_config

SKILLS = '''\
from mmexec.skills.base import FailureKind, Param, SkillFailure, skill


@skill("{name}", params=[Param("times", int, default=1)])
def greet(ctx, times=1):
    """Report hello ``times`` times, one per tick."""
    for _ in range(times):
        ctx.emit("report", message="hello", level="info")
        yield
    if times < 0:
        raise SkillFailure(FailureKind.PRECONDITION, "negative")
    return {{}}
'''

MISSION = """\
mission: greet
tree:
  skill: {name}
  params: {{times: 2}}
"""


def lab(tmp_path: Path, package: str, *, paths: str = "[src]") -> tuple[Path, Path]:
    """A user's project: ``lab/src/PACKAGE/skills.py``, ``lab/config.yaml`` naming it
    through ``skills.paths``, ``lab/missions/greet.yaml`` using its skill."""
    root = tmp_path / "lab"
    pkg = root / "src" / package
    pkg.mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "skills.py").write_text(SKILLS.format(name=f"greet_{package}"))
    config = root / "config.yaml"
    config.write_text(f"backend: mock\nskills:\n  paths: {paths}\n  modules: [{package}.skills]\n")
    (root / "missions").mkdir()
    mission = root / "missions" / "greet.yaml"
    mission.write_text(MISSION.format(name=f"greet_{package}"))
    return config, mission


def no_pythonpath() -> dict[str, str]:
    return {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}


def test_a_run_imports_the_config_folders_modules_without_pythonpath(tmp_path: Path) -> None:
    config, mission = lab(tmp_path, "sp_lab_run")
    elsewhere = tmp_path / "cwd"
    elsewhere.mkdir()
    exe = Path(sys.executable).with_name("mmexec")
    res = subprocess.run([str(exe), "run", str(mission), "--config", str(config), "--log", str(tmp_path / "r.jsonl")],
                         check=False, cwd=elsewhere, env=no_pythonpath(), capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    assert "request 1/1 (-): success" in res.stdout and res.stdout.count("hello") == 2


def test_skill_paths_stay_inside_the_config_tree_or_a_root(tmp_path: Path) -> None:
    config, _ = lab(tmp_path, "sp_lab_rules")
    assert load_config(config).skill_paths == (Path(os.path.realpath(tmp_path / "lab" / "src")),)
    shared = tmp_path / "shared"
    shared.mkdir()
    config.write_text("backend: mock\nskills:\n  paths: [src, ../shared, nowhere]\n")
    with pytest.raises(InputError) as ei:
        load_config(config)
    lines = str(ei.value).splitlines()
    assert len(lines) == 2
    assert lines[0].startswith(f"{config}:3:16: skills.paths[1]: '../shared' is outside the folders skill modules "
                               f"may come from ({os.path.realpath(tmp_path / 'lab')}); name its folder in 'roots:'")
    assert lines[1] == f"{config}:3:27: skills.paths[2]: 'nowhere' is not a folder ({tmp_path / 'lab' / 'nowhere'})"
    config.write_text("backend: mock\nroots: [../shared]\nskills:\n  paths: [src, ../shared, /etc]\n")
    with pytest.raises(InputError, match=r"skills.paths\[2\]: '/etc' is outside the folders"):
        load_config(config)
    config.write_text("backend: mock\nroots: [../shared]\nskills:\n  paths: [src, ../shared]\n")
    assert load_config(config).skill_paths == (Path(os.path.realpath(tmp_path / "lab" / "src")),
                                               Path(os.path.realpath(shared)))


def test_validate_and_skills_use_the_paths(run_cli, tmp_path: Path) -> None:
    config, mission = lab(tmp_path, "sp_lab_cli")
    res = run_cli("validate", mission, "--config", config)
    assert res.rc == 0, res.err
    res = run_cli("skills", "greet_sp_lab_cli", "--config", config)
    assert res.rc == 0 and "greet_sp_lab_cli  (from: sp_lab_cli.skills; needs nothing)" in res.out


def test_a_campaign_trial_finds_the_modules_through_the_config_alone(tmp_path: Path,
                                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    from mmexec.executive.campaign import CampaignOptions, run_campaign

    monkeypatch.delenv("PYTHONPATH", raising=False)
    config, mission = lab(tmp_path, "sp_lab_campaign")
    out = tmp_path / "camp"
    with open(os.devnull, "w") as null:
        _, results = run_campaign(CampaignOptions(mission=mission, config=config, trials=1, out=out, workers=1,
                                                  progress=False), out=null)
    assert [r.outcome for r in results] == ["success"], results
    generated = load_yaml(out / "config.yaml")
    src = os.path.realpath(tmp_path / "lab" / "src")
    assert generated["skills"]["paths"] == [src] and generated["roots"] == [src]
    assert results[0].command.startswith(f"mmexec run {mission} --config {out / 'config.yaml'} --seed ")


def test_a_campaign_reports_a_module_error_against_the_users_config(run_cli, tmp_path: Path) -> None:
    config, mission = lab(tmp_path, "sp_lab_broken")
    (tmp_path / "lab" / "src" / "sp_lab_broken" / "skills.py").write_text("raise RuntimeError('no lab today')\n")
    res = run_cli("campaign", mission, "--config", config, "--trials", "1", "--out", tmp_path / "camp")
    assert res.rc == 2
    assert res.err.strip() == (f"{config}:4:13: skills.modules[0]: cannot import 'sp_lab_broken.skills': "
                               "RuntimeError: no lab today")


# --------------------------------------------------------------------------- docs/testing.md

TESTING_MD = Path(__file__).resolve().parents[2] / "docs" / "testing.md"
#: a fenced block whose first line names a file of the example project
BLOCK = re.compile(r"^```\w*\n# (my_lab/\S+)( \(continued\))?\n(.*?)^```", re.DOTALL | re.MULTILINE)


def test_the_flow_of_testing_md_runs_as_written(tmp_path: Path) -> None:
    """The example project of docs/testing.md, written from its code blocks, passes each
    command of "Your own package, start to finish", with no PYTHONPATH."""
    files: dict[str, str] = {}
    for m in BLOCK.finditer(TESTING_MD.read_text()):
        name, continued, body = m.groups()
        files[name] = (files[name] if continued else "") + body
    assert {"my_lab/config.yaml", "my_lab/src/my_lab/skills.py", "my_lab/missions/present.yaml",
            "my_lab/tests/test_present.py", "my_lab/pyproject.toml"} <= set(files)
    files["my_lab/src/my_lab/__init__.py"] = ""
    for name, text in files.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    section = TESTING_MD.read_text().split("Then, from any folder:", 1)[1]
    commands = section.split("```\n", 2)[1].splitlines()
    exe = str(Path(sys.executable).with_name("mmexec"))
    env = no_pythonpath()
    ran: list[str] = []
    for line in commands:
        argv = shlex.split(line.split("  #", 1)[0])
        if argv[0] == "(cd":  # (cd my_lab && python -m pytest -q)
            cwd, argv = tmp_path / "my_lab", [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider"]
        else:
            cwd, argv = tmp_path, [exe, *argv[1:]]
        if "campaign" in argv:
            argv[argv.index("--trials") + 1] = "2"
        res = subprocess.run(argv, check=False, cwd=cwd, env=env, capture_output=True, text=True, timeout=300)
        assert res.returncode == 0, (line, res.stdout[-2000:], res.stderr[-2000:])
        assert "Traceback" not in res.stderr, line
        ran.append(argv[1] if argv[0] == exe else res.stdout.strip().splitlines()[-1])
    assert ran == ["skills", "validate", "run", ran[3], "campaign"] and re.match(r"3 passed in ", ran[3]), ran
