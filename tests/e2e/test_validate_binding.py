"""`mmexec validate MISSION --config CONFIG` checks skill needs against the configured
robot WITHOUT opening anything: the real-robot configs name serial ports and sockets that
do not exist here, so any attempt to open them would fail the validation."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from mmexec.executive import cli
from mmexec.executive.config import load_config

MISSION = "trees/fetch_item.yaml"


@pytest.mark.parametrize("config, backend", [
    ("config/locobot.yaml", "robot"),
    ("config/ur5e.yaml", "robot"),
    ("config/locobot_sim.yaml", "sim"),
    ("config/ur5e_sim.yaml", "sim"),
])
def test_fetch_mission_binds_to_every_shipped_config(run_cli, repo_root: Path, config: str, backend: str) -> None:
    res = run_cli("validate", repo_root / MISSION, "--config", repo_root / config)
    assert res.rc == 0, res.err
    assert f"binds to backend {backend!r}" in res.out
    assert "pybullet build time" not in res.err  # the skill modules' import banner is silenced


def test_real_robot_capabilities_come_from_the_plan_not_from_devices(repo_root: Path, monkeypatch) -> None:
    import mmexec.drivers.robot as robot_backend
    import mmexec.executive.config as config_mod

    def no_build(*a, **k):
        raise AssertionError("validate must not build (open) the real robot")

    monkeypatch.setattr(robot_backend, "build", no_build)
    monkeypatch.setattr(config_mod, "build_robot", no_build)
    caps = cli.binding_capabilities(load_config(repo_root / "config/locobot.yaml"))
    assert caps == {"base", "arm", "gripper", "camera"}
    caps = cli.binding_capabilities(load_config(repo_root / "config/ur5e.yaml"))
    assert caps == {"base", "arm", "gripper", "camera"}


def test_mock_capabilities_follow_its_section(tmp_path: Path) -> None:
    c = tmp_path / "c.yaml"
    c.write_text("backend: mock\nmock:\n  capabilities: [arm, gripper]\n")
    assert cli.binding_capabilities(load_config(c)) == {"arm", "gripper"}


def test_a_robot_without_a_base_is_one_line_per_leaf_and_exit_2(run_cli, repo_root: Path, tmp_path: Path) -> None:
    text = (repo_root / "config/ur5e.yaml").read_text()
    start = text.index("  base:\n")
    end = text.index("  arm:\n")
    fixed = tmp_path / "ur5e_fixed.yaml"
    fixed.write_text(text[:start] + text[end:])
    shutil.copytree(repo_root / "config" / "maps", tmp_path / "maps")  # robot.map is relative to the config
    res = run_cli("validate", repo_root / MISSION, "--config", fixed)
    assert res.rc == 2
    lines = res.err.strip().splitlines()
    assert lines and all("Traceback" not in ln for ln in lines)
    assert any(ln.endswith(f"skill 'navigate' needs a base, and backend 'robot' in {fixed} has none") for ln in lines)
    # every line is located in a mission file
    assert all(ln.split(":")[0].endswith(".yaml") and ln.split(":")[1].isdigit() for ln in lines), lines


def test_a_bad_robot_section_is_located_without_opening_ports(run_cli, repo_root: Path, tmp_path: Path) -> None:
    c = tmp_path / "bad.yaml"
    c.write_text("backend: robot\nrobot:\n  base: {kind: kobuki, port: /dev/nope, max_linaer: 0.3}\n")
    res = run_cli("validate", repo_root / MISSION, "--config", c)
    assert res.rc == 2
    assert f"{c}:3:" in res.err and "max_linaer" in res.err and "max_linear" in res.err
    assert "/dev/nope" not in res.err  # nothing tried to open the port
