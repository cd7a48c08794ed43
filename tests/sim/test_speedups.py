"""What makes the simulator fast must not change what it simulates: physics pauses only
at rest and resumes for any motion, the base's clearance map never claims clearance that
is not there, and the lidar still sees (and now flags) the world's reflectors."""

from __future__ import annotations

import math

import numpy as np
import pybullet as p
import pytest

from mmexec.drivers.interfaces import GoalState, Pose2D
from mmexec.sim.backend import build
from mmexec.sim.capabilities import SimLidar
from mmexec.sim.clearance import ClearanceMap
from mmexec.sim.world import load_world


def test_physics_pauses_at_rest_and_resumes_for_motion(sim_section, bench_world):
    r = build(sim_section(f"world: {bench_world}\n"), profile={}, seed=0, options={})
    try:
        r.spin(3.0)  # items settle and fall asleep
        poses = r.truth.item_poses()
        steps = r.physics_steps
        r.spin(1.0)
        assert r.physics_steps == steps  # nothing can change: no physics ran
        assert all(np.array_equal(poses[n], T) for n, T in r.truth.item_poses().items())
        g = r.arm.move_to([0.3, -0.5, 0.5, 0.0, 0.3, 0.0])
        while not g.done() and r.clock.now() < 20.0:
            r.spin(0.1)
        assert g.state is GoalState.SUCCEEDED and r.physics_steps > steps
        assert np.allclose(r.arm.state().positions, [0.3, -0.5, 0.5, 0.0, 0.3, 0.0], atol=0.01)
        # driving past an item within the arm's reach steps physics; far from items it need not
        r.spin(2.0)
        r.core.place_base(Pose2D(1.0, 1.0, math.pi / 2))  # 'cube' is 1.2 m away, 'big' 1.2 m
        steps = r.physics_steps
        r.base.set_velocity(0.2, 0.0)
        r.spin(0.5)
        assert r.physics_steps == steps and r.truth.base_pose().y > 1.05
        r.core.place_base(Pose2D(1.3, 1.8, math.pi / 2))  # 'cube' 0.5 m ahead, within reach
        r.base.set_velocity(0.2, 0.0)
        r.spin(0.5)
        assert r.physics_steps > steps
    finally:
        r.close()


def _box_distance(x: float, y: float, T: np.ndarray, size) -> float:
    dx, dy = x - T[0, 3], y - T[1, 3]
    lx, ly = T[0, 0] * dx + T[1, 0] * dy, T[0, 1] * dx + T[1, 1] * dy
    ex, ey = max(0.0, abs(lx) - size[0] / 2), max(0.0, abs(ly) - size[1] / 2)
    return math.hypot(ex, ey)


def test_clearance_map_is_a_lower_bound_and_tight_in_the_open():
    w = load_world("lab")
    cm = ClearanceMap.from_world(w, 0.0, 0.5)
    boxes = [(T, s) for _, T, s, _ in w.static_boxes() if T[2, 3] - s[2] / 2 <= 0.5]
    rng = np.random.default_rng(1)
    gaps = []
    for x, y in rng.uniform((0.0, 0.0), (5.0, 4.0), size=(400, 2)):
        exact = min(_box_distance(x, y, T, s) for T, s in boxes)
        lb = cm.lower_bound(x, y)
        assert lb <= exact + 1e-9, (x, y, lb, exact)
        gaps.append(exact - lb)
    assert float(np.median(gaps)) < 0.05  # close enough that the exact test is rare
    assert cm.lower_bound(-5.0, 1.0) == 0.0 and not cm.clear(-5.0, 1.0, 0.1)


def test_base_bumper_still_stops_at_obstacles_with_the_clearance_map(sim_section):
    r = build(sim_section("world: lab\nphysics_hz: 60\n"), profile={}, seed=0, options={})
    try:
        r.core.place_base(Pose2D(2.0, 1.3, 0.0))  # 'bin' cylinder (r 0.15) centred at (2.7, 1.3)
        for _ in range(40):
            r.base.set_velocity(0.4, 0.0)
            r.spin(0.1)
        x = r.truth.base_pose().x
        assert "bumper_centre" in r.base.state().faults
        assert 2.7 - 0.15 - r.base.bump_radius - 0.03 < x < 2.7 - 0.15 - 0.178 + 0.01
        assert r.base.exact_checks < 40 * 6  # most substeps were cleared by the map
    finally:
        r.close()


def test_lidar_flags_reflectors(sim_section):
    r = build(sim_section("world: lab\nlidar: {noise: 0.0, beams: 720}\n"), profile={}, seed=0, options={})
    try:
        r.core.place_base(Pose2D(1.0, 0.3, 0.3))  # south of the plant's pot, which hides refl_sw from (1, 1)
        scan = r.lidar.scan()
        assert scan is not None and scan.intensities is not None and scan.intensities.shape == scan.ranges.shape
        T = r.core.base_T() @ scan.T_base_lidar
        yaw = math.atan2(T[1, 0], T[0, 0])
        flagged = scan.intensities == SimLidar.REFLECTOR_INTENSITY
        posts = {rf.name: rf.position for rf in r.world.spec.reflectors}
        # every flagged beam ends on the 25 mm radius of a reflector post; the nearest
        # post (refl_sw, 0.92 m away in the open) is seen
        seen = set()
        for a, rng_ in zip(scan.angles[flagged], scan.ranges[flagged]):
            hx, hy = T[0, 3] + rng_ * math.cos(yaw + a), T[1, 3] + rng_ * math.sin(yaw + a)
            name, d = min(((n, math.hypot(hx - x, hy - y)) for n, (x, y) in posts.items()), key=lambda t: t[1])
            assert d == pytest.approx(0.025, abs=0.005), (name, d)
            seen.add(name)
        assert "refl_sw" in seen
        others = scan.intensities[~flagged]
        assert set(np.unique(others)) <= {0.0, SimLidar.SURFACE_INTENSITY}
        assert np.all((others == 0.0) == ~np.isfinite(scan.ranges[~flagged]))
    finally:
        r.close()


def test_floor_renders_without_gaps(sim_section, bench_world):
    """The collision plane used to be drawn too and z-fought with the floor."""
    r = build(sim_section(f"world: {bench_world}\ncamera: {{width: 160, height: 120, tilt: 0.6}}\n"),
              profile={}, seed=0, options={})
    try:
        r.core.place_base(Pose2D(1.0, 1.5, math.pi / 2))
        f = r.camera.frame()
        low = f.rgb[-30:].reshape(-1, 3).astype(int)  # bottom rows: floor only
        assert np.all(np.abs(low - low[0]).max(axis=1) <= 3)
        assert np.all(np.isfinite(f.depth[-30:]))
    finally:
        r.close()


def test_world_bodies_keep_static_pairs_out_of_the_broadphase(sim_section, bench_world):
    r = build(sim_section(f"world: {bench_world}\n"), profile={}, seed=0, options={})
    try:
        r.spin(0.5)
        h = r.scene_handles
        pairs = {(c[1], c[2]) for c in p.getContactPoints(physicsClientId=r.cid)}
        assert not {(h.static, h.floor), (h.floor, h.static)} & pairs
        assert not any(r.core.body in pr for pr in pairs)  # robot touches nothing at rest
    finally:
        r.close()
