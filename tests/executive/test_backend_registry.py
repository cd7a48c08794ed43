"""The registry of backends (:mod:`mmexec.executive.backends`) is the only place a backend
is named: every backend module declares a :class:`~mmexec.drivers.backendspec.BackendSpec`,
and a fourth, test-only backend (``bench``, tests/executive/bench_backend.py) registered
with one registry entry loads, validates, runs a mission, is refused run options it does
not honour and takes part in campaigns, with no other change anywhere."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from mmexec.config.yamlload import InputError, Mark
from mmexec.drivers.backendspec import CAPABILITIES, OPTIONS, BackendSpec
from mmexec.executive import backends
from mmexec.executive.campaign.faults import (
    AS_WRITTEN,
    BUILTIN_PROFILES,
    NOMINAL,
    apply_fault_profile,
    builtin_profile,
)
from mmexec.executive.campaign.requests import world_markers
from mmexec.executive.config import load_config

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]

PROFILE = """profile:
  home: [0.0, 0.0, 0.0]
  places:
    shelf: [1.5, 0.5, 0.0]
    table: [0.0, 1.2, 1.5708]
  named_poses:
    home:  [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    reach: [0.0, 0.4, 0.2, 0.0, -0.6, 0.0]
    carry: [0.0, -0.8, 1.0, 0.0, 0.6, 0.0]
"""


@pytest.fixture
def bench(monkeypatch: pytest.MonkeyPatch) -> None:
    """The ``bench`` backend registered as any backend is: one entry in the registry."""
    monkeypatch.syspath_prepend(str(HERE))
    monkeypatch.setitem(backends.BACKENDS, "bench", "bench_backend")


def write(tmp_path: Path, section: str, name: str = "bench.yaml") -> Path:
    p = tmp_path / name
    p.write_text("backend: bench\nrate_hz: 20\n" + section + PROFILE)
    return p


# --------------------------------------------------------------------------- every backend


def test_every_registered_backend_declares_a_consistent_spec() -> None:
    for name, spec in zip(backends.names(), backends.specs(Mark("<test>", 1, 1)), strict=True):
        assert isinstance(spec, BackendSpec) and spec.name == name
        assert spec.options <= set(OPTIONS)
        # a backend's fault patches are for built-in profiles that start from its faults-off patch
        assert set(spec.fault_patches) <= set(BUILTIN_PROFILES) - {AS_WRITTEN, NOMINAL}, name
    assert backends.names() == ("mock", "sim", "robot")


def test_the_backends_answer_from_their_sections_alone(tmp_path: Path) -> None:
    mock = tmp_path / "m.yaml"
    mock.write_text("backend: mock\nmock: {capabilities: [arm, gripper]}\n")
    assert load_config(mock).capabilities() == {"arm", "gripper"}
    assert load_config(REPO / "config" / "locobot_sim.yaml").capabilities() == set(CAPABILITIES)
    robot = tmp_path / "r.yaml"
    robot.write_text("backend: robot\nrobot:\n  lidar: {kind: rplidar, port: /dev/nope,\n"
                     "          pose_in_base: {xyz: [0, 0, 0.3], rpy: [0, 0, 0]}}\n")
    assert load_config(robot).capabilities() == {"lidar"}  # nothing opened: /dev/nope does not exist


def test_importing_the_registry_loads_no_backend() -> None:
    code = ("import sys, mmexec.executive.backends, mmexec.executive.config\n"
            "heavy = ('pybullet', 'mmexec.sim', 'mmexec.drivers.robot', 'mmexec.drivers.mock', 'mmexec.drivers.ur',\n"
            "         'mmexec.drivers.kobuki', 'mmexec.drivers.dynamixel', 'mmexec.drivers.robotiq',\n"
            "         'mmexec.drivers.rplidar', 'mmexec.drivers.camera')\n"
            "print(sorted(m for m in sys.modules if m.startswith(heavy)))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


# --------------------------------------------------------------------------- a fourth backend


def test_a_registered_backend_gets_its_config_keys(bench: None, tmp_path: Path) -> None:
    loaded = load_config(write(tmp_path, "bench: {grasps: [false]}\n"))
    assert loaded.backend == "bench" and loaded.spec.name == "bench"
    assert loaded.capabilities() == set(CAPABILITIES)
    p = tmp_path / "typos.yaml"
    p.write_text("backend: bnch\nbenhc: {}\n")
    with pytest.raises(InputError) as ei:
        load_config(p)
    assert str(ei.value).splitlines() == [
        f"{p}:1:10: backend: expected one of 'mock', 'sim', 'robot', 'bench', got 'bnch'; did you mean 'bench'?",
        f"{p}:2:1: benhc: unknown key; did you mean 'bench'?",
    ]
    p.write_text("backend: bench\nbench: [grasps]\n")
    with pytest.raises(InputError, match=r"typos.yaml:2:8: bench: expected a mapping of backend options"):
        load_config(p)


def test_a_registered_backend_validates(bench: None, run_cli, tmp_path: Path) -> None:
    mission = REPO / "trees" / "demo_mock.yaml"
    res = run_cli("validate", mission, "--config", write(tmp_path, "bench: {grasps: [false]}\n"))
    assert (res.rc, res.err) == (0, "")
    assert "binds to backend 'bench'" in res.out
    fixed = write(tmp_path, "bench:\n  rig: [arm, gripper]\n  grasp: []\n", "fixed.yaml")
    res = run_cli("validate", mission, "--config", fixed)
    assert res.rc == 2
    assert res.err.splitlines() == [f"{fixed}:5:3: bench.grasp: unknown key; did you mean 'grasps'?"]
    fixed.write_text(fixed.read_text().replace("  grasp: []\n", ""))
    res = run_cli("validate", mission, "--config", fixed)
    assert res.rc == 2
    assert any(line.endswith(f"skill 'drive_to' needs a base, and backend 'bench' in {fixed} has none")
               for line in res.err.splitlines()), res.err


def test_a_registered_backend_runs_a_mission(bench: None, run_cli, tmp_path: Path) -> None:
    log = tmp_path / "run.jsonl"
    res = run_cli("run", REPO / "trees" / "demo_mock.yaml", "--config", write(tmp_path, "bench: {grasps: [false]}\n"),
                  "--request", "item=1", "--log", log, "--seed", "3")
    assert res.rc == 0, res.err
    records = [json.loads(line) for line in log.read_text().splitlines()]
    start = next(r for r in records if r["event"] == "run_start")
    assert start["backend"] == "bench"
    end = next(r for r in records if r["event"] == "request_end")
    assert end["outcome"] == "success" and end["recoveries"] == 1  # the scripted first grasp found nothing


def test_a_registered_backend_is_refused_options_it_does_not_declare(bench: None, run_cli, tmp_path: Path) -> None:
    cfg = write(tmp_path, "")
    res = run_cli("run", REPO / "trees" / "demo_mock.yaml", "--config", cfg, "--request", "item=1",
                  "--log", tmp_path / "run.jsonl", "--gui")
    assert res.rc == 2
    assert res.err.splitlines() == [(f"{cfg}:1:10: backend: 'bench' cannot honour --gui (the simulator window; "
                                     "only backend 'sim' can): run without it or use a sim config")]


def test_a_registered_backend_declares_its_fault_patches(bench: None) -> None:
    cfg = {"backend": "bench", "bench": {"rig": ["arm", "gripper"], "grasps": [True], "dropouts": [1]}}
    assert apply_fault_profile(cfg, builtin_profile("nominal"), randomize=True)["bench"] == {"rig": ["arm", "gripper"]}
    assert apply_fault_profile(cfg, builtin_profile("arm_fail_first"), randomize=True)["bench"] == \
        {"rig": ["arm", "gripper"], "grasps": [False]}  # and no randomize key: it draws no world
    assert apply_fault_profile(cfg, builtin_profile("config"), randomize=True) == cfg
    with pytest.raises(InputError) as ei:
        apply_fault_profile(cfg, builtin_profile("sensor_dropout"), randomize=True)
    assert str(ei.value) == ("--faults: fault profile 'sensor_dropout' has no patch for backend 'bench' "
                             "(it has: sim)")
    with pytest.raises(InputError) as ei:
        world_markers(cfg, Mark("--draw", 1, 1))
    assert str(ei.value) == "--draw:1:1: @markers needs a sim config (the marker ids of the world's items)"
