"""Run config loading, binding errors with positions, skill modules, backend factory."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from mmexec.config.yamlload import InputError, Mark
from mmexec.drivers.mock import MockRobot
from mmexec.executive.config import (
    build_robot,
    load_config,
    load_skill_modules,
    robot_capabilities,
)
from mmexec.skills.base import REGISTRY

REPO = Path(__file__).resolve().parents[2]


def write(tmp_path: Path, text: str, name: str = "cfg.yaml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def test_shipped_mock_config_loads_and_builds() -> None:
    loaded = load_config(REPO / "config" / "mock.yaml")
    assert loaded.backend == "mock" and loaded.config.rate_hz == 20.0
    assert len(loaded.sha256) == 64
    robot = build_robot(loaded, seed=1)
    assert isinstance(robot, MockRobot)
    assert robot_capabilities(robot) == {"base", "arm", "gripper", "camera", "lidar"}
    assert robot.profile["named_poses"]["carry"][1] == -0.8
    assert robot.gripper.grasps == [False]


def test_binding_errors_carry_file_line_col(tmp_path: Path) -> None:
    p = write(tmp_path, "backend: mok\nrate_hz: fast\nskils: {}\nmock: 3\n")
    with pytest.raises(InputError) as ei:
        load_config(p)
    lines = str(ei.value).splitlines()
    assert lines == [
        f"{p}:1:10: backend: expected one of 'mock', 'sim', 'robot', got 'mok'; did you mean 'mock'?",
        f"{p}:2:10: rate_hz: expected a number, got 'fast'",
        f"{p}:3:1: skils: unknown key; did you mean 'skills'?",
        f"{p}:4:7: mock: expected a mapping of backend options, got 3",
    ]


def test_missing_backend_and_bad_rate(tmp_path: Path) -> None:
    p = write(tmp_path, "rate_hz: 0\n")
    with pytest.raises(InputError) as ei:
        load_config(p)
    assert "backend: missing required key" in str(ei.value)
    p = write(tmp_path, "backend: mock\nrate_hz: -5\n")
    with pytest.raises(InputError, match=r"cfg.yaml:1:1: rate_hz: expected a tick rate in \[1, 1000\] Hz"):
        load_config(p)


def test_not_a_mapping_and_missing_file(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="expected a mapping"):
        load_config(write(tmp_path, "- a\n- b\n"))
    with pytest.raises(InputError, match="nope.yaml:1:1: no such file"):
        load_config(tmp_path / "nope.yaml")


def test_backend_section_errors_reach_user(tmp_path: Path) -> None:
    p = write(tmp_path, "backend: mock\nmock:\n  arm: {fail_moves: [0]}\n")
    loaded = load_config(p)
    with pytest.raises(InputError, match=r"cfg.yaml:3:8: mock.arm: fail_moves: move numbers start at 1"):
        build_robot(loaded)


def test_missing_backend_module_is_one_line_error(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    from mmexec.executive import backends

    monkeypatch.setitem(backends.BACKENDS, "robot", "mmexec.drivers.not_built_yet_xyz")
    with pytest.raises(InputError) as ei:
        backends.backend_spec("robot", Mark("c.yaml", 1, 10))
    assert str(ei.value) == ("c.yaml:1:10: backend: 'robot' is not available in this installation "
                             "(module mmexec.drivers.not_built_yet_xyz not found)")
    with pytest.raises(InputError) as ei:
        load_config(write(tmp_path, "backend: robot\n"))  # found when the config loads
    assert str(ei.value) == (f"{tmp_path / 'cfg.yaml'}:1:10: backend: 'robot' is not available in this "
                             "installation (module mmexec.drivers.not_built_yet_xyz not found)")
    with pytest.raises(InputError, match="unknown backend 'ros'"):
        backends.backend_spec("ros", Mark("c.yaml", 1, 10))


def test_skill_modules_import_and_errors(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    pkg = tmp_path / "mylab_skills_t1.py"
    pkg.write_text(
        "from mmexec.skills.base import skill\n"
        "@skill('mylab_t1_hello')\n"
        "def hello(ctx):\n"
        "    yield\n"
        "    return {}\n"
    )
    (tmp_path / "mylab_broken_t1.py").write_text("def oops(:\n")
    (tmp_path / "mylab_raises_t1.py").write_text("raise RuntimeError('no license')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    p = write(tmp_path, "backend: mock\nskills:\n  modules: [mylab_skills_t1]\n")
    load_skill_modules(load_config(p))
    assert "mylab_t1_hello" in REGISTRY and "drive_to" in REGISTRY

    p = write(
        tmp_path,
        "backend: mock\nskills:\n  modules:\n    - mylab_nothere_t1\n    - mylab_broken_t1\n    - mylab_raises_t1\n",
    )
    with pytest.raises(InputError) as ei:
        load_skill_modules(load_config(p))
    lines = str(ei.value).splitlines()
    assert len(lines) == 3
    assert lines[0] == f"{p}:4:7: skills.modules[0]: cannot import 'mylab_nothere_t1': no such module"
    assert lines[1].startswith(f"{p}:5:7: skills.modules[1]: cannot import 'mylab_broken_t1': SyntaxError")
    assert lines[2] == f"{p}:6:7: skills.modules[2]: cannot import 'mylab_raises_t1': RuntimeError: no license"
    for name in ("mylab_skills_t1", "mylab_broken_t1", "mylab_raises_t1"):
        sys.modules.pop(name, None)
