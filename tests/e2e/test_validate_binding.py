"""`mmexec validate MISSION --config CONFIG` checks skill needs against the configured
robot WITHOUT opening anything: the real-robot configs name serial ports and sockets that
do not exist here, so any attempt to open them would fail the validation."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

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
    import dataclasses

    import mmexec.drivers.robot as robot_backend
    import mmexec.executive.config as config_mod

    def no_build(*a, **k):
        raise AssertionError("validate must not build (open) the real robot")

    monkeypatch.setattr(robot_backend, "BACKEND", dataclasses.replace(robot_backend.BACKEND, build=no_build))
    monkeypatch.setattr(config_mod, "build_robot", no_build)
    for config in ("config/locobot.yaml", "config/ur5e.yaml"):
        loaded = load_config(repo_root / config)
        caps = loaded.capabilities()
        assert caps >= {"base", "arm", "gripper", "camera"}, config
        assert caps == {line.split(":")[0] for line in robot_backend.check(loaded.section())}, config


def test_mock_capabilities_follow_its_section(tmp_path: Path) -> None:
    c = tmp_path / "c.yaml"
    c.write_text("backend: mock\nmock:\n  capabilities: [arm, gripper]\n")
    assert load_config(c).capabilities() == {"arm", "gripper"}


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


# --------------------------------------------------------------------------- the whole binding
#
# `validate --config` checks the robot profile (unknown keys with a hint, types, ranges) and
# every base pose it names on the map the run will have: inside it, free for the base's
# footprint, reachable from home. A profile mistake used to pass validate and surface mid-run.


def _room_map(folder: Path) -> Path:
    """A 4 x 2 m room (0.05 m cells, origin (0, 0)) split by a wall at x 2.0..2.1 m: the
    right half cannot be reached from the left."""
    import numpy as np

    from mmexec.drivers.interfaces import OccupancyGrid, Pose2D
    from mmexec.drivers.maps import write_map

    data = np.zeros((40, 80), dtype=np.int8)
    data[0, :] = data[-1, :] = data[:, 0] = data[:, -1] = 100
    data[:, 40:42] = 100
    yaml_path, _pgm = write_map(OccupancyGrid(data, 0.05, Pose2D(0.0, 0.0, 0.0)), folder / "room.yaml")
    return yaml_path


#: a real-robot config with a base only (nothing is opened by validate), on the split room
ROOM_CONFIG = """\
backend: robot
robot:
  base: {kind: kobuki, port: /dev/nope}
  map: {yaml: room.yaml}
profile:
  home: [0.5, 1.0, 0.0]
  places:
    outside: [5.0, 1.0, 0.0]
    in_wall: [2.05, 1.0, 0.0]
    too_close: [1.8, 1.0, 0.0]
  fetch:
    depot: {base: [1.0, 0.5, 0.0], place: [1.0, 0.2, 0.3]}
    settle_time: 0.2
  search:
    locations:
      - [1.0, 1.5, 0.0]
      - [3.0, 1.0, 3.14]
  camera: {detect_frames: three}
  nav: {max_vv: 0.3}
  arm: {velocity_scale: 1.5}
"""


def _room(tmp_path: Path, text: str = ROOM_CONFIG) -> Path:
    _room_map(tmp_path)
    cfg = tmp_path / "room_robot.yaml"
    cfg.write_text(text)
    return cfg


def test_every_profile_and_pose_problem_is_located_and_reported_at_once(run_cli, repo_root: Path,
                                                                        tmp_path: Path) -> None:
    cfg = _room(tmp_path)
    res = run_cli("validate", repo_root / MISSION, "--config", cfg)
    assert res.rc == 2
    lines = res.err.strip().splitlines()
    assert all("Traceback" not in ln for ln in lines)
    # every line is FILE:LINE:COL: ... (the mission's lines: the robot has no arm, gripper, camera)
    for ln in lines:
        file, line, col, _rest = ln.split(":", 3)
        assert file.endswith(".yaml") and line.isdigit() and col.isdigit(), ln
    config_lines = [ln.removeprefix(f"{cfg}:") for ln in lines if ln.startswith(f"{cfg}:")]
    assert config_lines == [
        "8:14: profile.places.outside: (5, 1) is outside robot.map (x 0..4 m, y 0..2 m)",
        "9:14: profile.places.in_wall: (2.05, 1) is in an obstacle of robot.map",
        ("10:16: profile.places.too_close: (1.8, 1) is 0.20 m from an obstacle of robot.map; the base needs "
         "0.208 m (footprint radius 0.178 m + nav margin 0.03 m)"),
        # a setting written where it was before the general sections (issue 10 item 5)
        ("13:5: profile.fetch.settle_time: unknown key; did you mean 'profile.search.settle_time'? "
         "(the setting moved there)"),
        ("17:9: profile.search.locations[1]: (3, 1) cannot be reached from profile.home (0.5, 1): "
         "no path in robot.map inflated by 0.208 m"),
        "18:27: profile.camera.detect_frames: expected an integer, got 'three'",
        "19:9: profile.nav.max_vv: unknown key; did you mean 'max_v'?",
        "20:25: profile.arm.velocity_scale: expected in (0, 1], got 1.5",
    ]
    mission_lines = [ln for ln in lines if ln.startswith(str(repo_root / "trees"))]
    assert any("skill 'pick' needs a arm" in ln for ln in mission_lines), mission_lines
    assert len(lines) == len(config_lines) + len(mission_lines)


def test_a_typo_in_a_section_name_gets_a_hint(run_cli, repo_root: Path, tmp_path: Path) -> None:
    cfg = _room(tmp_path, ROOM_CONFIG.replace("  places:\n", "  plaecs:\n"))
    res = run_cli("validate", repo_root / MISSION, "--config", cfg)
    assert res.rc == 2
    assert f"{cfg}:7:3: profile.plaecs: unknown profile section; did you mean 'places'?" in res.err.splitlines()
    # a nested setting written at the top level is pointed at where it belongs
    cfg.write_text("backend: mock\nprofile:\n  tcp_offset: 0.155\n")
    res = run_cli("validate", repo_root / "trees/demo_mock.yaml", "--config", cfg)
    assert res.err.splitlines() == [
        f"{cfg}:3:3: profile.tcp_offset: unknown profile section; did you mean 'arm.tcp_offset'?"]


def test_sim_poses_are_checked_on_the_world_map(run_cli, repo_root: Path, tmp_path: Path) -> None:
    text = (repo_root / "config/locobot_sim.yaml").read_text()
    depot = "      base: [2.5, 3.2, 1.5708]"
    assert depot in text
    cfg = tmp_path / "sim.yaml"
    cfg.write_text(text.replace(depot, "      base: [2.7, 1.3, 1.5708]"))   # inside the lab's bin
    res = run_cli("validate", repo_root / MISSION, "--config", cfg)
    assert res.rc == 2
    line = next(i for i, ln in enumerate(text.splitlines(), 1) if ln.startswith(depot))
    assert res.err.splitlines() == [
        f"{cfg}:{line}:13: profile.fetch.depot.base: (2.7, 1.3) is in an obstacle of the map of world 'lab'"]


def test_a_bad_world_is_located_with_the_profile_problems(run_cli, repo_root: Path, tmp_path: Path) -> None:
    text = (repo_root / "config/locobot_sim.yaml").read_text()
    cfg = tmp_path / "sim.yaml"
    cfg.write_text(text.replace("  world: lab\n", "  world: lba\n").replace("settle_time: 0.2", "settle_time: -1"))
    res = run_cli("validate", repo_root / MISSION, "--config", cfg)
    assert res.rc == 2
    lines = res.err.splitlines()
    world_line = text.splitlines().index("  world: lab") + 1
    settle_line = next(i for i, ln in enumerate(text.splitlines(), 1) if "settle_time: 0.2" in ln)
    assert len(lines) == 2, lines
    assert lines[0].startswith(f"{cfg}:{world_line}:10: unknown world 'lba'") and "did you mean 'lab'?" in lines[0]
    assert lines[1] == f"{cfg}:{settle_line}:18: profile.search.settle_time: expected >= 0 s, got -1"


@pytest.mark.parametrize("config", sorted(p.name for p in (Path(__file__).parents[2] / "config").glob("*.yaml")))
def test_every_shipped_config_validates_clean_with_the_fetch_mission(run_cli, repo_root: Path, config: str) -> None:
    res = run_cli("validate", repo_root / MISSION, "--config", repo_root / "config" / config)
    assert (res.rc, res.err) == (0, ""), res.err


def test_run_rejects_a_profile_problem_before_building_the_robot(run_cli, repo_root: Path, tmp_path: Path) -> None:
    text = (repo_root / "config/mock.yaml").read_text()
    cfg = tmp_path / "mock.yaml"
    cfg.write_text(text.replace("  home: [0.0, 0.0, 0.0]", "  hom: [0.0, 0.0, 0.0]"))
    log = tmp_path / "run.jsonl"
    res = run_cli("run", repo_root / "trees/demo_mock.yaml", "--config", cfg, "--request", "item=1", "--log", log)
    assert res.rc == 2
    assert res.err.splitlines() == [f"{cfg}:18:3: profile.hom: unknown profile section; did you mean 'home'?"]
    assert not log.exists()  # nothing started


@pytest.mark.parametrize("flag", [["--gui"], ["--record", "video.mp4"]])
def test_run_options_a_backend_cannot_honour_are_errors(run_cli, repo_root: Path, tmp_path: Path,
                                                        flag: list[str]) -> None:
    cfg = tmp_path / "bare_robot.yaml"
    cfg.write_text("# a robot with no devices\nbackend: robot\nrobot: {name: bare}\n")
    res = run_cli("run", repo_root / "trees/demo_mock.yaml", "--config", cfg, "--request", "item=1",
                  "--log", tmp_path / "run.jsonl", *flag)
    assert res.rc == 2
    assert res.err.splitlines() == [f"{cfg}:2:10: backend: 'robot' cannot honour {flag[0]} ("
                                    + ("the simulator window" if flag[0] == "--gui" else "a video of the simulation")
                                    + "; only backend 'sim' can): run without it or use a sim config"]
    assert not (tmp_path / "video.mp4").exists()


def test_a_named_pose_typo_is_found_before_the_robot_drives(run_cli, repo_root: Path, tmp_path: Path) -> None:
    """arm.stow names a pose of profile.named_poses: a typo there used to pass validate
    and fail the first arm move of the run, after the robot had driven to the shelf."""
    text = (repo_root / "config/locobot_sim.yaml").read_text()
    stow = "    stow: tuck"
    line = next(i for i, ln in enumerate(text.splitlines(), 1) if ln.startswith(stow))
    cfg = tmp_path / "sim.yaml"
    cfg.write_text(text.replace(stow, "    stow: tuk "))
    res = run_cli("validate", repo_root / MISSION, "--config", cfg)
    assert (res.rc, res.err.splitlines()) == (2, [
        f"{cfg}:{line}:11: profile.arm.stow: 'tuk' is not one of profile.named_poses; did you mean 'tuck'?"])
