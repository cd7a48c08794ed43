"""The UR3e + Robotiq 2F-85 description against Universal Robots' published numbers
(docs/robots.md 2.1-2.2): the official DH table, written out here once more rather than
read from the description, its zero-configuration flange position, the joint limits
(wrist 3 turns without limit, in the simulator too), and the platform it shares with the
UR5e."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mmexec.drivers import descriptions
from mmexec.drivers.descriptions import dh_transform, ur
from mmexec.drivers.interfaces import GoalState, JointTrajectory
from mmexec.sim.backend import build
from mmexec.skills.manipulation.kinematics import ArmKinematics

UR3E = descriptions.get("ur3e_robotiq")

#: UR's DH table of the UR3e: d, a [m] and alpha [rad] per joint
D = (0.15185, 0.0, 0.0, 0.13105, 0.08535, 0.0921)
A = (0.0, -0.24355, -0.2132, 0.0, 0.0, 0.0)
ALPHA = (math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0)
#: ROS ``base_link`` from the controller's ``base``: pi about z
RZ = np.diag([-1.0, -1.0, 1.0, 1.0])


def vendor_dh(q: np.ndarray) -> np.ndarray:
    """``T_base_tool0`` from UR's table by the standard DH convention, in the controller's
    ``base``."""
    T = np.eye(4)
    for i in range(6):
        T = T @ dh_transform(float(q[i]), D[i], A[i], ALPHA[i])
    return T


def test_the_zero_configuration_flange_is_urs() -> None:
    kin = ArmKinematics.from_description(UR3E, tcp_offset=0.0)
    T = kin.fk(np.zeros(6))
    assert np.allclose(T[:3, 3], (0.45675, 0.22315, 0.0665), atol=1e-9)  # docs/robots.md 2.1, base_link
    assert np.allclose(T[:3, 2], (0.0, 1.0, 0.0), atol=1e-12)  # tool0's z along +y of base_link (2.3)
    assert np.allclose(ur.forward_kinematics(np.zeros(6), "ur3e")[:3, 3], (-0.45675, -0.22315, 0.0665), atol=1e-9)


def test_forward_kinematics_is_the_vendor_dh_at_random_configurations() -> None:
    kin = ArmKinematics.from_description(UR3E, tcp_offset=0.0)
    rng = np.random.default_rng(11)
    for _ in range(50):
        q = rng.uniform(-2 * math.pi, 2 * math.pi, 6)
        expect = vendor_dh(q)
        assert np.allclose(kin.fk(q), RZ @ expect, atol=1e-9), q
        assert np.allclose(ur.forward_kinematics(q, "ur3e"), expect, atol=1e-9), q


def test_the_grasp_point_is_the_2f85s_on_the_tool_axis() -> None:
    assert UR3E.arm is not None and UR3E.arm.tcp_offset == pytest.approx(0.155)
    kin = ArmKinematics.from_description(UR3E)
    q = np.array([0.3, -1.2, 1.1, -0.7, 0.4, 2.0])
    T = RZ @ vendor_dh(q)
    assert np.allclose(kin.fk(q)[:3, 3], T[:3, 3] + 0.155 * T[:3, 2], atol=1e-9)


def test_limits_are_the_ur3es() -> None:
    assert UR3E.arm is not None
    lims = {lim.name: lim for lim in UR3E.arm.limits}
    speeds = (math.pi, math.pi, math.pi, 2 * math.pi, 2 * math.pi, 2 * math.pi)
    torques = (54.0, 54.0, 28.0, 9.0, 9.0, 9.0)
    bounds = (2 * math.pi, 2 * math.pi, math.pi, 2 * math.pi, 2 * math.pi, math.inf)
    for name, speed, torque, bound in zip(ur.JOINT_NAMES, speeds, torques, bounds):
        lim = lims[name]
        assert (lim.lower, lim.upper, lim.velocity, lim.effort) == (-bound, bound, speed, torque), name
    joints = {j.name: j for j in UR3E.urdf_tree().joints}
    assert joints["wrist_3_joint"].kind == "continuous"
    assert all(joints[n].kind == "revolute" for n in ur.JOINT_NAMES[:5])


def test_it_stands_on_the_ur5e_platform() -> None:
    ur5e = descriptions.get("ur5e_robotiq")
    assert UR3E.arm_mount == ur5e.arm_mount
    assert UR3E.info.footprint_radius == ur5e.info.footprint_radius
    assert UR3E.grasp_links == ur5e.grasp_links
    assert UR3E.info.arm_joints == ur5e.info.arm_joints == ur.JOINT_NAMES
    base = {ln.name: ln for ln in ur5e.urdf_tree().links}
    for link in UR3E.urdf_tree().links:
        if link.name in ("mobile_base_link", "laser_frame_link", "robotiq_base_link", "camera_link"):
            assert link == base[link.name], link.name
    masses = {ln.name: ln.mass for ln in UR3E.urdf_tree().links}
    # UR's link masses (docs/robots.md 2.1), not the UR5e's
    assert [masses[n] for n in ("shoulder_link", "upper_arm_link", "forearm_link", "wrist_1_link",
                                "wrist_2_link", "wrist_3_link")] == [1.98, 3.4445, 1.437, 0.871, 0.805, 0.261]


def test_the_simulated_ur3e_turns_wrist_3_without_limit() -> None:
    robot = build({"robot": "ur3e_robotiq"}, profile={}, seed=0, options={})
    try:
        assert robot.description is UR3E
        lims = {lim.name: lim for lim in robot.arm.limits}
        assert (lims["wrist_3_joint"].lower, lims["wrist_3_joint"].upper) == (-math.inf, math.inf)
        assert lims["wrist_3_joint"].velocity == pytest.approx(2 * math.pi)
        assert (lims["elbow_joint"].lower, lims["elbow_joint"].upper) == pytest.approx((-math.pi, math.pi))
        q0 = list(robot.arm.state().positions)
        goal = robot.arm.follow(JointTrajectory(ur.JOINT_NAMES, (3.0,), ((*q0[:5], 7.0),)))
        robot.spin(3.5)
        assert goal.state is GoalState.SUCCEEDED, goal
        assert robot.arm.state().positions[5] == pytest.approx(7.0, abs=0.01)
    finally:
        robot.close()
