"""Closed-form ray casts (sim/raycast.py) against pybullet's rayTestBatch: the same hits
within pybullet's own tolerance over the shipped worlds with people, exact distances on
known geometry, and pybullet's answers for whatever has no closed form here."""

from __future__ import annotations

import json
import math

import numpy as np
import pybullet as p
import pytest

from mmexec.config.yamlload import load_yaml_text
from mmexec.drivers.interfaces import Pose2D
from mmexec.sim.backend import build
from mmexec.sim.raycast import SceneRays


def _robot(robot: str, world: str, seed: int = 5, raycast: str = "pybullet"):
    sec = {"robot": robot, "world": world, "randomize": True, "faults": {"crowd": {}},
           "lidar": {"noise": 0.0, "raycast": raycast}}
    return build(load_yaml_text(json.dumps(sec), "config.yaml"), profile={}, seed=seed, options={})


def _scan_rays(r, tilt: float = 0.0):
    c, lid = r.core, r.lidar
    T = c.link_T(c.info.lidar_link)
    d = lid._dirs.copy()
    if tilt:
        d[:, 2] = math.sin(tilt)
        d /= np.linalg.norm(d, axis=1)[:, None]
    d = d @ T[:3, :3].T
    o = T[:3, 3]
    return o, o + d * lid.range_min, o + d * lid.range_max, d, lid.range_max - lid.range_min


def _compare(r, poses: int, tilt: float = 0.0, seed: int = 1) -> tuple[float, np.ndarray, int]:
    """Fraction of beams whose hit body/link differ, and the range differences [m] of the
    beams that agree, over ``poses`` random free poses."""
    c = r.core
    rays = SceneRays(r.cid, [r.scene_handles.static, r.scene_handles.floor], c.people.bodies if c.people else [])
    rng = np.random.default_rng(seed)
    sx, sy = r.world.spec.room.size
    differ, total, diffs, done = 0, 0, [], 0
    while done < poses:
        x, y, th = rng.uniform(0, sx), rng.uniform(0, sy), rng.uniform(-math.pi, math.pi)
        if not c.clearance.clear(x, y, r.base.bump_radius + 0.02):
            continue
        if c.people is not None and (c.people.gaps(x, y, r.base.bump_radius + 0.3) < 0).any():
            continue
        c.place_base(Pose2D(x, y, th))
        done += 1
        o, s, e, d, length = _scan_rays(r, tilt)
        ref = p.rayTestBatch(s.tolist(), e.tolist(), physicsClientId=r.cid)
        got = rays.cast(s, e, d, length, origin=o)
        rb = np.array([h[0] for h in ref])
        rl = np.array([h[1] for h in ref])
        rf = np.array([h[2] if h[0] >= 0 else np.inf for h in ref])
        same = (rb == got.body) & (rl == got.link)
        differ += int((~same).sum())
        total += len(rb)
        hit = same & np.isfinite(rf)
        assert np.array_equal(np.isfinite(rf[same]), np.isfinite(got.fraction[same]))
        diffs.append(np.abs(rf[hit] - got.fraction[hit]) * length)
        # unit normals on every hit, facing the ray
        n = got.normal[np.isfinite(got.fraction)]
        assert np.allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-6)
        assert np.all(np.einsum("ij,ij->i", n, d[np.isfinite(got.fraction)]) <= 1e-9)
    return differ / total, np.concatenate(diffs), rays.cast(s, e, d, length, origin=o).cast


@pytest.mark.parametrize(("robot", "world"), [("locobot_wx250s", "lab"), ("ur5e_robotiq", "lab"),
                                               ("locobot_wx250s", "corridors")])
def test_level_scans_agree_with_pybullet_within_its_tolerance(robot, world):
    r = _robot(robot, world)
    try:
        r.spin(0.5)
        differ, diffs, _ = _compare(r, 25)
    finally:
        r.close()
    assert differ < 0.005  # beams grazing an edge or a person within pybullet's ~1 mm
    assert np.percentile(diffs, 99) < 0.0015
    assert np.median(diffs) < 1e-4


def test_tilted_scans_take_the_general_path_and_agree_too():
    r = _robot("locobot_wx250s", "lab")
    try:
        differ, diffs, _ = _compare(r, 8, tilt=-0.08)  # beams reach the floor plane and the boards
    finally:
        r.close()
    assert differ < 0.01
    assert np.percentile(diffs, 99) < 0.0015


def test_exact_distances_on_known_shapes_and_none_from_within():
    cid = p.connect(p.DIRECT)
    try:
        box = p.createCollisionShape(p.GEOM_BOX, halfExtents=[0.5, 0.2, 1.0], physicsClientId=cid)
        cyl = p.createCollisionShape(p.GEOM_CYLINDER, radius=0.3, height=2.0, physicsClientId=cid)
        q = p.getQuaternionFromEuler((0, 0, math.radians(30)))
        fixed = p.createMultiBody(0, -1, -1, [0, 0, 0], linkMasses=[0, 0], linkCollisionShapeIndices=[box, cyl],
                                  linkVisualShapeIndices=[-1, -1], linkPositions=[[3, 0, 1], [0, 4, 1]],
                                  linkOrientations=[q, [0, 0, 0, 1]], linkInertialFramePositions=[[0, 0, 0]] * 2,
                                  linkInertialFrameOrientations=[[0, 0, 0, 1]] * 2, linkParentIndices=[0, 0],
                                  linkJointTypes=[p.JOINT_FIXED] * 2, linkJointAxis=[[0, 0, 1]] * 2,
                                  physicsClientId=cid)
        rays = SceneRays(cid, [fixed])
        o = np.array([0.0, 0.0, 0.5])
        d = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
        s, e = o + 0.1 * d, o + 10.0 * d
        got = rays.cast(s, e, d, 9.9, origin=o)
        # the box turned 30 deg: the x axis meets its -y face (0.2 m from the centre) first,
        # 0.2 / sin(30 deg) before the centre; pybullet's convex cast agrees to its tolerance
        assert got.fraction[0] * 9.9 + 0.1 == pytest.approx(3 - 0.2 / math.sin(math.radians(30)), abs=1e-12)
        ref = p.rayTestBatch(s.tolist(), e.tolist(), physicsClientId=cid)
        assert [h[1] for h in ref] == got.link.tolist()
        assert ref[0][2] * 9.9 + 0.1 == pytest.approx(2.6, abs=1e-3)
        assert got.fraction[1] * 9.9 + 0.1 == pytest.approx(4 - 0.3, abs=1e-12)
        assert (got.link[0], got.link[1], got.link[2]) == (0, 1, -1) and not np.isfinite(got.fraction[2])
        np.testing.assert_allclose(got.normal[1], [0, -1, 0], atol=1e-12)
        # from inside the cylinder, as pybullet: no hit on it
        inside = np.array([[0.0, 4.0, 0.5]])
        got = rays.cast(inside, inside + [[0, 5, 0]], np.array([[0.0, 1.0, 0.0]]), 5.0, origin=inside[0])
        ref = p.rayTestBatch(inside.tolist(), (inside + [[0, 5, 0]]).tolist(), physicsClientId=cid)
        assert got.body[0] == ref[0][0] == -1
    finally:
        p.disconnect(cid)


def test_anything_without_a_closed_form_is_left_to_pybullet():
    """An item (a dynamic body) in the scan's plane is seen, as pybullet sees it."""
    r = _robot("locobot_wx250s", "lab", raycast="closed_form")
    try:
        c = r.core
        o, _, _, _, _ = _scan_rays(r)
        item = r.scene_handles.items[r.world.item_names()[0]]
        bearing = c.true_pose.theta + 0.3
        at = [o[0] + 0.8 * math.cos(bearing), o[1] + 0.8 * math.sin(bearing), o[2]]
        p.resetBasePositionAndOrientation(item, at, [0, 0, 0, 1], physicsClientId=r.cid)
        r.spin(1 / r.clock.hz)
        scan = r.lidar.scan()
        ref = _robot("locobot_wx250s", "lab")
        try:
            p.resetBasePositionAndOrientation(ref.scene_handles.items[r.world.item_names()[0]], at, [0, 0, 0, 1],
                                              physicsClientId=ref.cid)
            ref.spin(1 / ref.clock.hz)
            want = ref.lidar.scan()
        finally:
            ref.close()
        assert scan is not None and want is not None
        on_item = want.ranges < 0.85  # the beams that meet the item (nothing else is that near)
        assert 2 <= on_item.sum() <= 10
        # pybullet's own answers (cast only as far as the item, so to its tolerance)
        np.testing.assert_allclose(scan.ranges[on_item], want.ranges[on_item], atol=1e-4)
        assert r.lidar._rays is not None and r.lidar._last is not None
        # reflectors read alike but for a beam grazing a post within pybullet's ~1 mm
        assert int((scan.intensities != want.intensities).sum()) <= 2
    finally:
        r.close()


def test_an_unknown_raycast_is_a_config_error(sim_section):
    from mmexec.config.yamlload import InputError
    from mmexec.sim.backend import parse_section

    assert parse_section(sim_section("lidar: {raycast: closed_form}\n")).lidar.raycast == "closed_form"
    with pytest.raises(InputError, match=r"config.yaml:1:.*raycast"):
        parse_section(sim_section("lidar: {raycast: fast}\n"))


def test_a_body_made_after_the_first_scan_is_seen():
    r = _robot("locobot_wx250s", "lab", raycast="closed_form")
    try:
        o, _, _, _, _ = _scan_rays(r)
        before = r.lidar.scan()
        yaw = r.core.true_pose.theta + 0.5
        col = p.createCollisionShape(p.GEOM_BOX, halfExtents=[0.05, 0.05, 0.5], physicsClientId=r.cid)
        p.createMultiBody(0, col, -1, [o[0] + 0.6 * math.cos(yaw), o[1] + 0.6 * math.sin(yaw), 0.5],
                          physicsClientId=r.cid)
        r.spin(1 / r.clock.hz)
        after = r.lidar.scan()
        assert before is not None and after is not None
        def near(scan) -> int:  # beams ending 0.5-0.6 m out: on the new post's face
            return int(((scan.ranges > 0.5) & (scan.ranges < 0.6)).sum())

        assert near(after) >= near(before) + 2
    finally:
        r.close()
