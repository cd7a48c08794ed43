"""The robot descriptions hold together: every name a description gives is in its link
tree, the PoE arm chain reaches the same tool pose as the tree's joints, the mount and
the limits are the tree's, and the registry reports unknown names with the known ones.

The link tree is walked here with plain numpy (URDF joint origins: xyz, then roll, pitch,
yaw about fixed axes; revolute joints turn about their axis, prismatic ones slide along
it), so these checks do not depend on pybullet; tests/sim/test_models.py checks the
written URDFs in pybullet against the vendors' numbers.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mmexec.drivers import descriptions
from mmexec.drivers.descriptions import DESCRIPTIONS, LinkTree, RobotDescription

ALL = list(DESCRIPTIONS.values())
IDS = list(DESCRIPTIONS)


def _rot(axis: tuple[float, float, float], angle: float) -> np.ndarray:
    k = np.asarray(axis, dtype=float)
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * K + (1.0 - math.cos(angle)) * (K @ K)


def _origin(xyz: tuple[float, float, float], rpy: tuple[float, float, float]) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = _rot((0, 0, 1), rpy[2]) @ _rot((0, 1, 0), rpy[1]) @ _rot((1, 0, 0), rpy[0])
    T[:3, 3] = xyz
    return T


def _link_pose(tree: LinkTree, frm: str, to: str, q: dict[str, float]) -> np.ndarray:
    """``T_frm_to`` through the tree's joints (``to`` must be below ``frm``), joint values
    ``q`` by joint name (0 for those not given)."""
    parent = {j.child: j for j in tree.joints}
    T = np.eye(4)
    link = to
    while link != frm:
        if link not in parent:
            raise AssertionError(f"{tree.name}: {to} is not below {frm}")
        j = parent[link]
        step = _origin(j.xyz, j.rpy)
        v = q.get(j.name, 0.0)
        if j.kind in ("revolute", "continuous"):
            move = np.eye(4)
            move[:3, :3] = _rot(j.axis, v)
            step = step @ move
        elif j.kind == "prismatic":
            move = np.eye(4)
            move[:3, 3] = np.asarray(j.axis) * v
            step = step @ move
        T = step @ T
        link = j.parent
    return T


@pytest.mark.parametrize("d", ALL, ids=IDS)
def test_every_name_the_description_gives_is_in_its_link_tree(d: RobotDescription) -> None:
    tree = d.urdf_tree()
    assert tree.name == d.name
    links = {ln.name for ln in tree.links}
    joints = {j.name: j for j in tree.joints}
    info = d.info
    named_links = {info.root_link, info.arm_base_link, info.tool_link, info.camera_link,
                   info.camera_optical_link, info.lidar_link, *info.finger_links, *info.bump_links,
                   *d.grasp_links}
    assert named_links <= links, sorted(named_links - links)
    named_joints = {*info.arm_joints, *info.gripper_joints, *info.pan_tilt_joints}
    assert named_joints <= set(joints), sorted(named_joints - set(joints))
    assert all(joints[n].kind == "prismatic" for n in info.gripper_joints)
    assert len(info.sleep_pose) == len(info.arm_joints)
    assert d.urdf_path.name == info.urdf and d.urdf_path.is_file()


@pytest.mark.parametrize("d", ALL, ids=IDS)
def test_the_arm_chain_reaches_the_link_trees_tool_pose(d: RobotDescription) -> None:
    assert d.arm is not None
    tree = d.urdf_tree()
    rng = np.random.default_rng(7)
    for i in range(30):
        qv = np.zeros(d.arm.dof) if i == 0 else rng.uniform(-math.pi, math.pi, d.arm.dof)
        T_tree = _link_pose(tree, d.info.arm_base_link, d.info.tool_link, dict(zip(d.arm.joint_names, qv)))
        T = np.eye(4)
        for k in range(d.arm.dof):  # the chain's PoE, written out once more
            w, v = d.arm.screws[:3, k], d.arm.screws[3:, k]
            step = np.eye(4)
            step[:3, :3] = _rot(w, qv[k])
            W = _rot(w, qv[k]) - np.eye(3)
            step[:3, 3] = (-W @ np.cross(w, v)) + np.dot(w, v) * w * qv[k]
            T = T @ step
        T = T @ d.arm.M
        assert np.allclose(T, T_tree, atol=2e-6), (d.name, qv)


@pytest.mark.parametrize("d", ALL, ids=IDS)
def test_limits_and_mount_are_the_link_trees(d: RobotDescription) -> None:
    assert d.arm is not None
    joints = {j.name: j for j in d.urdf_tree().joints}
    for lim in d.arm.limits:
        j = joints[lim.name]
        assert (j.lower, j.upper, j.velocity, j.effort) == (lim.lower, lim.upper, lim.velocity, lim.effort), lim.name
        assert lim.acceleration == math.inf  # a planner sets it from arm.acceleration
    mount = _link_pose(d.urdf_tree(), d.info.root_link, d.info.arm_base_link, {})
    assert np.allclose(mount[:3, 3], d.arm_mount, atol=1e-9)
    assert np.allclose(mount[:3, :3], np.eye(3), atol=1e-9)


@pytest.mark.parametrize("d", ALL, ids=IDS)
def test_gripper_width_and_joint_values_round_trip(d: RobotDescription) -> None:
    info = d.info
    joints = {j.name: j for j in d.urdf_tree().joints}
    lo, hi = info.gripper_width_range
    assert 0.0 <= lo < hi
    for width in np.linspace(lo, hi, 9):
        q = info.width_to_q(float(width))
        assert info.q_to_width(*q) == pytest.approx(width, abs=1e-12)
        for name, value in zip(info.gripper_joints, q):
            assert joints[name].lower - 1e-12 <= value <= joints[name].upper + 1e-12, (name, width)


def test_the_arm_arrays_are_read_only() -> None:
    arm = descriptions.get("ur5e_robotiq").arm
    assert arm is not None
    with pytest.raises(ValueError):
        arm.M[0, 3] = 1.0
    with pytest.raises(ValueError):
        arm.screws[0, 0] = 1.0


def test_the_registry_names_the_known_descriptions() -> None:
    assert descriptions.names() == tuple(DESCRIPTIONS) == ("locobot_wx250s", "ur5e_robotiq", "ur3e_robotiq")
    assert all(descriptions.get(n).name == n for n in descriptions.names())
    with pytest.raises(KeyError, match=r"unknown robot model 'locobot_wx200'; did you mean 'locobot_wx250s'\? "
                                       r"\(known: locobot_wx250s, ur5e_robotiq, ur3e_robotiq\)"):
        descriptions.get("locobot_wx200")


def test_a_description_that_contradicts_itself_is_refused() -> None:
    d = descriptions.get("locobot_wx250s")
    with pytest.raises(ValueError, match="model info is named 'locobot_wx250s'"):
        RobotDescription("other", d.info, d.arm, d.arm_mount, d.gripper_links, d.urdf_tree)
    ur = descriptions.get("ur5e_robotiq")
    with pytest.raises(ValueError, match="arm chain joints"):
        RobotDescription(d.name, d.info, ur.arm, d.arm_mount, d.gripper_links, d.urdf_tree)
