"""Localisation against the simulated LoCoBot (issue 11): the sim's RPLIDAR A2 model and
``realistic`` odometry, the ``kidnap`` and ``reflector_dropout`` faults, the reflectors
mapgen writes, and the reflector-enhanced AMCL tracking the robot through all of it."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from mmexec.config.yamlload import InputError, load_yaml_text
from mmexec.drivers.geometry import wrap_angle as wrap
from mmexec.drivers.interfaces import LaserScan, Pose2D
from mmexec.drivers.maps import load_map, write_map
from mmexec.sim import mapgen
from mmexec.sim.backend import SimRobot, build, parse_section
from mmexec.sim.capabilities import ODOMETRY_PROFILES
from mmexec.sim.world import load_world
from mmexec.skills.localization import AmclConfig, ParticleFilter, ReflectorConfig, load_reflectors
from mmexec.skills.localization.reflectors import extract_reflectors
from mmexec.skills.navigation.astar import plan_path, simplify_path
from mmexec.skills.navigation.grid import CostMap, inflate
from mmexec.skills.navigation.tracker import PathTracker, TrackerConfig

#: the RPLIDAR A2 as the localisation benchmark models it
A2 = {"noise": 0.002, "noise_fraction": 0.0075, "quality": "rplidar_a2"}


def _robot(seed: int, **extra: Any) -> SimRobot:
    section = {"world": "lab", "physics_hz": 60, "lidar": A2, "odometry_noise": {"profile": "realistic"}, **extra}
    return build(section, profile={}, seed=seed, options={})  # type: ignore[arg-type]


def _bright_runs(scan: LaserScan) -> int:
    """How many reflectors the scan shows (runs of high-intensity beams)."""
    return len(extract_reflectors(scan.ranges, scan.angles, scan.intensities, ReflectorConfig(post_radius=0.025)))


class Drive:
    """The robot driven through goals on its TRUE pose (the filter is measured, not used),
    a scan every 0.1 s fed to a reflector-enhanced filter built from mapgen's map."""

    def __init__(self, robot: SimRobot, tmp: Path, guess_error: tuple[float, float, float]) -> None:
        self.r = robot
        yaml_path, _ = write_map(robot.world.occupancy(0.05), tmp / "lab.yaml", reflectors=robot.world.spec.reflectors)
        grid, refl = load_map(yaml_path), load_reflectors(yaml_path)
        self.costmap: CostMap = inflate(grid, robot.base.radius, 0.05)
        scan = robot.lidar.scan()
        assert scan is not None
        T = scan.T_base_lidar
        mount = (float(T[0, 3]), float(T[1, 3]), math.atan2(T[1, 0], T[0, 0]))
        self.pf = ParticleFilter(grid, AmclConfig(reflectors=refl.config()), reflectors=refl.positions, mount=mount,
                                 rng=np.random.default_rng(7))
        s = robot.truth.base_pose()
        self.pf.initialise((s.x + guess_error[0], s.y + guess_error[1], s.theta + guess_error[2]))
        self.ticks = 0
        #: per scan: (sim time [s], filter position error [m], filter heading error [rad], odometry position error [m])
        self.log: list[tuple[float, float, float, float]] = []

    def to(self, x: float, y: float, theta: float) -> None:
        r = self.r
        here = r.truth.base_pose()
        assert self.costmap.is_free(x, y)
        path = plan_path(self.costmap, (here.x, here.y), (x, y))
        assert path is not None
        tracker = PathTracker(simplify_path(self.costmap, path), TrackerConfig(max_v=0.5, max_w=1.5), theta)
        done = False
        while not done:
            st = r.base.state()
            v, w, done = tracker.step(r.truth.base_pose(), st.v, st.w, 0.05)
            r.base.set_velocity(v, w)
            r.spin(0.05)
            self.ticks += 1
            if self.ticks % 2 == 0:
                self.feed()

    def feed(self) -> None:
        r = self.r
        scan = r.lidar.scan()
        assert scan is not None
        odom = r.base.state().pose
        self.pf.update((odom.x, odom.y, odom.theta), scan.ranges, scan.angles, scan.range_max, scan.intensities)
        m = self.pf.map_to_odom()
        x, y, _ = m @ np.array([odom.x, odom.y, 1.0])
        t = r.truth.base_pose()
        heading = float(wrap(math.atan2(m[1, 0], m[0, 0]) + odom.theta - t.theta))
        self.log.append((r.clock.now(), math.hypot(x - t.x, y - t.y), abs(heading), math.hypot(odom.x - t.x, odom.y - t.y)))


ROUTE = [(3.6, 2.0, -1.5), (3.6, 0.9, 3.1), (1.2, 1.0, 1.6), (1.2, 2.9, 0.0), (2.2, 2.2, 0.0)]


def test_the_enhanced_filter_tracks_the_sim_locobot_within_2_cm_while_odometry_drifts(tmp_path: Path) -> None:
    robot = _robot(seed=3)
    try:
        drive = Drive(robot, tmp_path, (0.08, -0.06, 0.05))
        for goal in ROUTE:
            drive.to(*goal)
    finally:
        robot.close()
    log = np.array(drive.log)
    tracked = log[log[:, 0] > 3.0]  # after 3 s to converge from the 10 cm, 0.05 rad guess
    assert robot.clock.now() > 25.0 and len(tracked) > 200
    assert tracked[:, 1].max() < 0.025   # 0.02 before the lab's panel and plant hid the south posts from most places
    assert tracked[:, 2].max() < 0.017
    assert tracked[:, 1].mean() < 0.01
    # odometry alone (the 'realistic' profile) drifts well beyond the filter
    assert log[:, 3].max() > 3 * tracked[:, 1].max()
    assert log[-1, 3] > 2 * log[-1, 1]


def test_kidnap_teleports_the_robot_once_the_odometry_does_not_notice_and_the_filter_recovers(tmp_path: Path) -> None:
    robot = _robot(seed=4, faults={"kidnap": {"at": 12.0, "pose": [3.6, 2.2, 1.0]}})
    try:
        drive = Drive(robot, tmp_path, (0.0, 0.0, 0.0))
        drive.to(2.4, 2.0, 0.0)  # 0.9 m from the lab's start pose
        assert robot.clock.now() < 11.0
        before = robot.truth.base_pose()
        odom_before = robot.base.state().pose
        while robot.clock.now() <= 12.0:
            robot.spin(0.05)
        after = robot.truth.base_pose()
        assert (after.x, after.y, after.theta) == pytest.approx((3.6, 2.2, 1.0))
        assert math.hypot(before.x - after.x, before.y - after.y) > 1.0
        odom = robot.base.state().pose
        assert (odom.x, odom.y, odom.theta) == (odom_before.x, odom_before.y, odom_before.theta)  # still, and unaware
        assert [f for _, f in robot.truth.faults_fired()] == ["kidnap to (3.600, 2.200, 1.000)"]
        kidnap_log = len(drive.log)
        drive.to(3.6, 0.9, 3.1)
        drive.to(2.2, 2.2, 0.0)
    finally:
        robot.close()
    assert [f for _, f in robot.truth.faults_fired()] == ["kidnap to (3.600, 2.200, 1.000)"]  # once
    after_kidnap = np.array(drive.log[kidnap_log:])
    assert after_kidnap[0, 1] > 1.0  # the first update after the kidnap is off
    found = after_kidnap[after_kidnap[:, 0] > after_kidnap[0, 0] + 3.0]  # 3 s of driving later
    assert found[:, 1].max() < 0.05 and found[:, 2].max() < 0.05  # the benchmark's "recovered"


def test_a_kidnap_without_a_pose_goes_somewhere_clear_and_far_the_same_for_a_seed() -> None:
    def land(seed: int) -> Pose2D:
        r = build({"world": "lab", "physics_hz": 60, "faults": {"kidnap": {"at": 0.5, "min_distance": 1.5}}},
                  profile={}, seed=seed, options={})  # type: ignore[arg-type]
        try:
            start = r.truth.base_pose()
            r.spin(1.0)
            pose = r.truth.base_pose()
            assert math.hypot(pose.x - start.x, pose.y - start.y) >= 1.5
            assert inflate(r.occupancy, r.base.radius, 0.0).is_free(pose.x, pose.y)
            r.base.set_velocity(0.1, 0.0)
            r.spin(0.5)
            assert not r.base.state().faults  # not stuck in anything
            return pose
        finally:
            r.close()

    assert land(5) == land(5)
    assert land(5) != land(6)


def test_reflector_dropout_covers_the_reflectors_for_its_interval_only() -> None:
    r = build({"world": "lab", "physics_hz": 60, "lidar": {"beams": 800, "noise": 0.0, "quality": "rplidar_a2"},
               "faults": {"reflector_dropout": {"intervals": [[1.0, 2.0]]}}},
              profile={}, seed=0, options={})  # type: ignore[arg-type]
    try:
        r.core.place_base(Pose2D(4.0, 2.5, 0.3))  # sees all six posts (the panel and the plant hide some elsewhere)
        before = r.lidar.scan()
        r.spin(1.5)
        during = r.lidar.scan()
        r.spin(1.0)
        after = r.lidar.scan()
    finally:
        r.close()
    assert before is not None and during is not None and after is not None
    assert _bright_runs(before) == 6 and _bright_runs(after) == 6
    assert _bright_runs(during) == 0
    assert np.array_equal(before.ranges, during.ranges)  # covered, not removed
    assert during.intensities is not None and during.intensities.max() <= 50 / 63
    assert any(f == "reflector_dropout" for _, f in r.truth.faults_fired())


def test_reflector_dropout_of_named_reflectors_leaves_the_others() -> None:
    r = build({"world": "lab", "lidar": {"beams": 800, "noise": 0.0},
               "faults": {"reflector_dropout": {"p": 1.0, "reflectors": ["refl_se"]}}},
              profile={}, seed=0, options={})  # type: ignore[arg-type]
    try:
        r.core.place_base(Pose2D(2.2, 2.0, 0.3))
        scan = r.lidar.scan()
    finally:
        r.close()
    assert scan is not None and scan.intensities is not None
    assert _bright_runs(scan) == 5  # the lab's six posts but refl_se
    assert set(np.unique(scan.intensities)) <= {0.0, 0.2, 1.0}  # the binary model, as before


def test_the_a2_lidar_model_noise_grows_with_range_and_quality_separates_reflectors() -> None:
    r = build({"world": "lab", "lidar": {"beams": 800, "noise": 0.0, "noise_fraction": 0.01, "quality": "rplidar_a2"}},
              profile={}, seed=1, options={})  # type: ignore[arg-type]
    exact = build({"world": "lab", "lidar": {"beams": 800, "noise": 0.0}}, profile={}, seed=1,
                  options={})  # type: ignore[arg-type]
    try:
        scans = []
        for robot in (r, exact):
            robot.core.place_base(Pose2D(1.0, 2.0, 0.0))
            scans.append([robot.lidar.scan() for _ in range(20)])
    finally:
        r.close()
        exact.close()
    truth = scans[1][0].ranges
    err = np.array([s.ranges - truth for s in scans[0]])
    near, far = truth < 1.5, truth > 3.5
    assert 0.006 < err[:, near].std() / np.mean(truth[near]) < 0.014
    assert 0.006 < err[:, far].std() / np.mean(truth[far]) < 0.014
    inten = np.array([s.intensities for s in scans[0]])
    q = np.round(inten * 63)
    assert np.allclose(inten * 63, q)  # quality / 63, as the driver reports it
    bright = inten >= 0.8
    assert bright.any() and inten[bright].min() >= 56 / 63 and inten[~bright & (inten > 0)].max() <= 50 / 63


def test_odometry_profiles_and_lidar_options_bind_and_refuse_bad_values() -> None:
    cfg = parse_section({"odometry_noise": {"profile": "realistic", "scale": 0.03}})
    assert cfg.odometry_noise.model() == replace(ODOMETRY_PROFILES["realistic"], scale=0.03)
    old = parse_section({"odometry_noise": {"linear": 0.05, "angular": 0.05}}).odometry_noise.model()
    assert (old.linear, old.angular, old.systematic) == (0.05, 0.05, False)  # the keys configs had keep their meaning
    assert not parse_section(None).odometry_noise.model().systematic  # a default run draws nothing new
    with pytest.raises(InputError, match=r"profile: expected one of 'default', 'realistic', got 'realstic'; did you mean 'realistic'"):
        parse_section({"odometry_noise": {"profile": "realstic"}})
    with pytest.raises(InputError, match="odometry noise gyro_bias must be >= 0"):
        parse_section({"odometry_noise": {"gyro_bias": -1.0}})
    with pytest.raises(InputError, match="lidar.quality: expected one of 'binary', 'rplidar_a2'"):
        parse_section({"lidar": {"quality": "a2"}})
    with pytest.raises(InputError, match="noise_fraction must be >= 0"):
        parse_section({"lidar": {"noise_fraction": -0.01}})


def test_faults_naming_what_the_world_lacks_are_refused_at_build() -> None:
    with pytest.raises(InputError, match=r"reflector_dropout.reflectors: no reflector 'refl_s' in world 'lab'; did you mean"):
        build({"world": "lab", "faults": {"reflector_dropout": {"reflectors": ["refl_s"]}}}, profile={}, seed=0,
              options={})  # type: ignore[arg-type]
    with pytest.raises(InputError, match=r"kidnap.pose: the base \(0.178 m radius\) at \(2.6, 0.4\) would overlap"):
        build({"world": "lab", "faults": {"kidnap": {"at": 1.0, "pose": [2.6, 0.4, 0.0]}}}, profile={}, seed=0,
              options={})  # type: ignore[arg-type]
    with pytest.raises(InputError, match="at must be >= 0 s"):
        parse_section({"faults": {"kidnap": {"at": -1.0}}})


def test_mapgen_writes_the_reflectors_beside_the_map_and_load_map_is_unchanged(tmp_path: Path) -> None:
    assert mapgen.main(["lab", str(tmp_path / "lab.yaml")]) == 0
    refl = load_reflectors(tmp_path / "lab.yaml")
    world = load_world("lab")
    assert refl.names == tuple(r.name for r in world.spec.reflectors)
    assert np.array_equal(refl.positions, np.array([r.position for r in world.spec.reflectors]))
    assert refl.radius == 0.025 and refl.config().post_radius == 0.025
    assert np.array_equal(load_map(tmp_path / "lab.yaml").data, world.occupancy(0.05).data)
    # the shipped real-robot map carries them too
    shipped = Path(__file__).resolve().parents[2] / "config" / "maps" / "lab.yaml"
    assert np.array_equal(load_reflectors(shipped).positions, refl.positions)


@pytest.mark.parametrize("name", sorted(p.stem for p in (Path(mapgen.__file__).parent / "worlds").glob("*.yaml")))
def test_every_shipped_worlds_map_carries_its_reflectors(tmp_path: Path, name: str) -> None:
    """The localiser's landmarks come with the map: a mapgen map file read back, and the
    navigation map the sim backend declares, list the world's reflector posts."""
    from mmexec.sim.backend import BACKEND, world_reflectors

    world = load_world(name, randomize=False)
    want = world_reflectors(world)
    assert len(want) >= 3, f"world {name!r}: the localiser needs three reflector posts for a fix"
    yaml_path, _ = write_map(world.occupancy(0.05), tmp_path / f"{name}.yaml", reflectors=world.spec.reflectors)
    assert load_map(yaml_path).reflectors == want
    assert BACKEND.navigation is not None
    nav = BACKEND.navigation(load_yaml_text(f"world: {name}\n", "sim.yaml"))
    assert nav is not None and nav.grid.reflectors == want


def test_the_sim_robots_map_carries_the_world_reflectors() -> None:
    r = _robot(0)
    try:
        assert [p.name for p in r.occupancy.reflectors] == [x.name for x in r.world.spec.reflectors]
        assert r.occupancy.reflectors[0].position == pytest.approx(r.world.spec.reflectors[0].position)
    finally:
        r.close()


def test_the_realistic_odometry_campaign_profile_sets_the_profile_and_combines() -> None:
    from mmexec.executive.campaign.faults import load_fault_profile, merge_patch

    prof = load_fault_profile("realistic_odometry")
    section = {"world": "lab", "odometry_noise": {"linear": 0.02}, "faults": {"kidnap": {"at": 3.0}}}
    out = section
    for patch in prof.patches["sim"]:
        out = merge_patch(out, patch)
    assert out["odometry_noise"] == {"linear": 0.02, "profile": "realistic"} and "faults" not in out
    assert parse_section(out).odometry_noise.model() == replace(ODOMETRY_PROFILES["realistic"], linear=0.02)
    both = load_fault_profile("crowd+realistic_odometry").patches["sim"]
    out = section
    for patch in both:
        out = merge_patch(out, patch)
    assert out["faults"] == {"crowd": {}} and out["odometry_noise"]["profile"] == "realistic"
    assert "mock" not in prof.patches   # sim only: the mock has no odometry to drift
