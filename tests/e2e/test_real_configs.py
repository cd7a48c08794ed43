"""The real-robot configs carry everything trees/fetch_item.yaml needs in a room built like
the sim's ``lab`` world: the map (config/maps/lab.*), the planning scene and the
profile sections (fetch, arm, camera, search; nav within the base's limits) of the
matching sim config. Checked without opening hardware:
the ``robot:`` section is planned (``mmexec.drivers.robot.check``) and only its map and
scene are built; ``mmexec run`` with no robot attached fails at once, in one line."""

from __future__ import annotations

import math
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from mmexec.config.yamlload import YDict
from mmexec.drivers import robot as robot_backend
from mmexec.drivers.kobuki.base import KobukiBase
from mmexec.executive.config import load_config, load_skill_modules
from mmexec.sim.models import MODEL_INFO
from mmexec.sim.world import load_world
from mmexec.skills.fetch import FetchProfile
from mmexec.skills.navigation.astar import plan_path
from mmexec.skills.navigation.grid import inflate
from mmexec.skills.profile import PROFILE

MISSION = "trees/fetch_item.yaml"

#: real config -> (its sim twin, the sim model whose footprint the real base has)
CONFIGS = {
    "config/locobot.yaml": ("config/locobot_sim.yaml", "locobot_wx250s"),
    "config/ur5e.yaml": ("config/ur5e_sim.yaml", "ur5e_robotiq"),
    "config/ur3e.yaml": ("config/ur3e_sim.yaml", "ur3e_robotiq"),
}


def _profile(loaded) -> dict[str, Any]:
    """The config's profile sections, bound (fetch, nav, arm, camera, search, ...), with
    every built-in skill module loaded, as a run loads them (each declares its section)."""
    load_skill_modules(loaded)
    raw = loaded.raw["profile"]
    bound, problems = PROFILE.check(raw, raw.mark)
    assert not problems, [str(p) for p in problems]
    assert isinstance(bound["fetch"], FetchProfile)
    return bound


def _map_and_scene_only(section: YDict) -> YDict:
    """The ``robot:`` section without its devices (marks kept, so ``map.yaml`` still
    resolves next to the config file): building it opens nothing."""
    keep = ("name", "map", "scene")
    out = YDict({k: v for k, v in section.items() if k in keep})
    out.mark = section.mark
    out.key_marks = {k: m for k, m in section.key_marks.items() if k in keep}
    out.value_marks = {k: m for k, m in section.value_marks.items() if k in keep}
    return out


def _within_a_cell(a, b) -> bool:
    import numpy as np

    def grow(m):
        p = np.pad(m, 1)
        return np.logical_or.reduce([p[1 + dr: 1 + dr + m.shape[0], 1 + dc: 1 + dc + m.shape[1]]
                                     for dr in (-1, 0, 1) for dc in (-1, 0, 1)])

    oa, ob = a >= 50, b >= 50
    return a.shape == b.shape and not (oa & ~grow(ob)).any() and not (ob & ~grow(oa)).any()


@pytest.fixture(scope="module")
def lab():
    return load_world("lab")  # nominal poses, as the map and scene were made


@pytest.mark.parametrize("config", list(CONFIGS))
def test_section_plans_every_device_and_loads_the_lab_map_and_scene(repo_root: Path, lab, config: str) -> None:
    loaded = load_config(repo_root / config)
    section = loaded.section()
    devices = robot_backend.check(section, profile=loaded.config.profile)   # opens nothing
    lidar = ["lidar"] if config == "config/locobot.yaml" else []   # the LoCoBot's RPLIDAR
    head = ["head"] if config == "config/locobot.yaml" else []     # and its pan/tilt head
    assert [d.split(":")[0] for d in devices] == ["base", "arm", "gripper", *head, "camera", *lidar]
    assert section["map"]["yaml"] == "maps/lab.yaml"   # relative to the config file
    robot = robot_backend.build(_map_and_scene_only(section), profile=loaded.config.profile, seed=None, options={})
    try:
        assert robot.base is None and robot.arm is None and robot.camera is None
        grid, sim = robot.occupancy, lab.occupancy(0.05)
        assert grid is not None and grid.resolution == pytest.approx(0.05)
        assert (grid.origin.x, grid.origin.y, grid.origin.theta) == pytest.approx((sim.origin.x, sim.origin.y, 0.0))
        assert _within_a_cell(grid.data, sim.data)
        want = lab.scene_boxes()
        assert [b.name for b in robot.scene] == [b.name for b in want]
        for got, exp in zip(robot.scene, want):
            assert tuple(got.size) == pytest.approx(exp.size, abs=1e-6), got.name
            assert got.pose == pytest.approx(exp.pose, abs=1e-5), got.name
    finally:
        robot.close()


@pytest.mark.parametrize("config", list(CONFIGS))
def test_fetch_profile_binds_and_mirrors_the_sim_config(repo_root: Path, lab, config: str) -> None:
    sim_config, _model = CONFIGS[config]
    loaded, sim = load_config(repo_root / config), load_config(repo_root / sim_config)
    profile = loaded.config.profile
    fp, sp = _profile(loaded), _profile(sim)
    # the lab's poses and the manipulation settings are the sim's; nav follows the base
    for key in ("fetch", "arm", "camera", "search"):
        assert fp[key] == sp[key], key
    for key in ("approach_distances", "refine_at", "redetect_at_standoff"):
        assert getattr(fp["nav"], key) == getattr(sp["nav"], key), key
    assert list(profile["home"]) == list(sim.config.profile["home"]) == list(lab.spec.start)
    assert list(loaded.raw["robot"]["base"]["start"]) == list(profile["home"])
    poses = profile["named_poses"]
    for role in ("stow", "carry", "look", "reach"):
        name = getattr(fp["arm"], role)
        assert name is None or (name in poses and len(poses[name]) == 6), (role, name)
    base = loaded.raw["robot"]["base"]
    nav = fp["nav"]
    assert nav.max_v <= base["max_linear"] and nav.max_w <= base["max_angular"]
    assert nav.accel_v <= base["linear_accel"] and nav.accel_w <= base["angular_accel"]


@pytest.mark.parametrize("config", list(CONFIGS))
def test_home_depot_and_search_locations_are_free_and_connected(repo_root: Path, config: str) -> None:
    _sim_config, model = CONFIGS[config]
    loaded = load_config(repo_root / config)
    prof = _profile(loaded)
    fp, margin = prof["fetch"], prof["nav"].margin
    robot = robot_backend.build(_map_and_scene_only(loaded.section()), profile={}, seed=None, options={})
    robot.close()  # nothing was opened; the map stays on it
    # navigate inflates the map by Base.radius (the Kobuki driver's, or the base section's
    # footprint_radius) plus nav.margin; that must cover the platform's footprint as the sim's does
    radius = loaded.raw["robot"]["base"].get("footprint_radius", KobukiBase.radius)
    assert radius + margin >= MODEL_INFO[model].footprint_radius + 0.03 - 1e-9
    cm = inflate(robot.occupancy, radius, margin)
    home = tuple(loaded.config.profile["home"])
    stops = {"home": home, "depot": fp.depot.base}
    stops.update({f"search.locations[{i}]": p for i, p in enumerate(prof["search"].locations)})
    for name, (x, y, _th) in stops.items():
        assert cm.is_free(x, y), f"{config}: {name} ({x}, {y}) is inside the inflated map"
        assert plan_path(cm, home[:2], (x, y)) is not None, f"{config}: no path from home to {name}"
    # the place point is over the depot basket, within the arm's reach of the depot stop
    px, py, _pz = fp.depot.place
    bx, by, bth = fp.depot.base
    assert math.hypot(px - bx, py - by) < 0.75
    assert abs(math.atan2(py - by, px - bx) - bth) < 0.3


@pytest.mark.parametrize("config", list(CONFIGS))
def test_validate_binds_the_fetch_mission(run_cli, repo_root: Path, config: str) -> None:
    res = run_cli("validate", repo_root / MISSION, "--config", repo_root / config)
    assert res.rc == 0, res.err
    assert "binds to backend 'robot'" in res.out


# --------------------------------------------------------------------------- run, no robot


def _mmexec() -> list[str]:
    script = Path(sys.executable).parent / "mmexec"
    if script.exists():
        return [str(script)]
    return [sys.executable, "-c", "import sys; from mmexec.executive.cli import main; sys.exit(main())"]


def _run(cwd: Path, config: str, log: Path) -> tuple[subprocess.CompletedProcess[str], float]:
    env = {k: v for k, v in os.environ.items() if k != "MMEXEC_DEBUG"}
    t0 = time.monotonic()
    res = subprocess.run(_mmexec() + ["run", MISSION, "--config", config, "--request", "item=3", "--log", str(log)],
                         check=False, cwd=cwd, capture_output=True, text=True, timeout=120, env=env)
    return res, time.monotonic() - t0


def _one_line(res: subprocess.CompletedProcess[str]) -> str:
    assert res.returncode == 2, (res.returncode, res.stdout, res.stderr)
    assert "Traceback" not in res.stderr + res.stdout
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1, lines
    return lines[0]


def test_run_without_the_robot_is_one_line_and_exit_2(repo_root: Path, tmp_path: Path) -> None:
    """The shipped config as it is: the first device it cannot bring up is named in one
    line located in the config: the RealSense when pyrealsense2 is missing (checked
    before any port is opened), else the Kobuki's port."""
    if Path("/dev/kobuki").exists():
        pytest.skip("a Kobuki is attached to this machine")
    res, took = _run(repo_root, "config/locobot.yaml", tmp_path / "run.jsonl")
    line = _one_line(res)
    assert line.startswith("config/locobot.yaml:")
    try:
        import pyrealsense2  # noqa: F401
    except ImportError:
        assert "robot.camera: realsense 0: pyrealsense2 is not installed" in line
    else:
        assert "robot.base: kobuki on /dev/kobuki: no such port" in line
    assert took < 60


@pytest.mark.parametrize("config, port", [("locobot.yaml", "/dev/kobuki"), ("ur5e.yaml", "/dev/ttyBase")])
def test_run_fails_fast_naming_the_base_and_its_port(repo_root: Path, tmp_path: Path, config: str, port: str) -> None:
    """Without the camera section (so pyrealsense2 does not matter), the base is brought
    up first: no such port -> one line naming the device and the port, exit 2, at once."""
    if Path(port).exists():
        pytest.skip(f"{port} exists on this machine")
    text = (repo_root / "config" / config).read_text()
    start = text.index("  camera:\n")
    # up to the lidar where there is one (the localiser needs it), else up to the map
    end = text.index("  lidar:\n") if "\n  lidar:\n" in text else text.index("  # The lab's occupancy map")
    (tmp_path / "config").mkdir()
    cfg = tmp_path / "config" / config
    cfg.write_text(text[:start] + text[end:])
    shutil.copytree(repo_root / "config" / "maps", tmp_path / "config" / "maps")
    shutil.copytree(repo_root / "trees", tmp_path / "trees")
    res, took = _run(tmp_path, f"config/{config}", tmp_path / "run.jsonl")
    line = _one_line(res)
    base_line = next(i for i, ln in enumerate(text.splitlines(), 1) if ln == "  base:")
    assert line.startswith(f"config/{config}:{base_line + 1}:")
    assert f"robot.base: kobuki on {port}: no such port" in line
    assert took < 60
