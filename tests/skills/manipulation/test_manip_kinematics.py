from __future__ import annotations

import math

import numpy as np
import pybullet as p
import pytest

from mmexec.skills.manipulation.kinematics import UR5E_DH, _dh, ur5e, wx250s
from mmexec.skills.perception.averaging import rotation_angle


def test_wx250s_zero_pose_matches_official_numbers():
    T = wx250s().fk(np.zeros(6))
    assert np.allclose(T[:3, 3], (0.458325, 0.0, 0.354825), atol=1e-3)
    assert np.allclose(T[:3, :3], np.eye(3))
    # LoCoBot frame tree: arm_base_link at (0.097277, 0, 0.10795) in base_footprint,
    # ee_gripper_link at (0.555602, 0, 0.462775)
    assert np.allclose(T[:3, 3] + (0.097277, 0, 0.10795), (0.555602, 0, 0.462775), atol=1e-3)
    T = wx250s(locobot=False).fk(np.zeros(6))
    assert np.allclose(T[:3, 3], (0.458325, 0.0, 0.36065), atol=1e-3)


def test_ur5e_zero_pose_and_dh_agreement():
    kin = ur5e(tcp_offset=0.0)
    T = kin.fk(np.zeros(6))
    assert np.allclose(T[:3, 3], (0.8172, 0.2329, 0.0628), atol=1e-3)
    # tool0 points along +y of base_link at zero: quat (0, -0.7071, -0.7071, 0)
    assert np.allclose(T[:3, 2], (0, 1, 0), atol=1e-9)
    x, y, z, w = 0.0, -math.sqrt(0.5), -math.sqrt(0.5), 0.0
    R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                  [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                  [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    assert rotation_angle(T[:3, :3], R) < 1e-6
    # PoE equals the DH chain (rotated into base_link) at random configurations
    rng = np.random.default_rng(1)
    for _ in range(20):
        q = rng.uniform(-math.pi, math.pi, 6)
        Tdh = np.diag([-1.0, -1.0, 1.0, 1.0])
        for th, (d, a, al) in zip(q, UR5E_DH):
            Tdh = Tdh @ _dh(th, d, a, al)
        assert np.allclose(kin.fk(q), Tdh, atol=1e-9)
    # the TCP offset moves the tool along its z
    Tt = ur5e().fk(np.zeros(6))
    assert np.allclose(Tt[:3, 3], T[:3, 3] + 0.155 * T[:3, 2])


def test_wx250s_matches_sim_model_urdf():
    from mmexec.sim.models import MODEL_INFO, urdf_path

    info = MODEL_INFO["locobot_wx250s"]
    cid = p.connect(p.DIRECT)
    try:
        r = p.loadURDF(str(urdf_path("locobot_wx250s")), useFixedBase=True, physicsClientId=cid)
        idx = {p.getJointInfo(r, i, physicsClientId=cid)[1].decode(): i for i in range(p.getNumJoints(r, physicsClientId=cid))}
        link = {p.getJointInfo(r, i, physicsClientId=cid)[12].decode(): i for i in range(p.getNumJoints(r, physicsClientId=cid))}
        kin = wx250s()
        rng = np.random.default_rng(2)
        for _ in range(10):
            q = rng.uniform(kin.lower, kin.upper)
            for j, v in zip(info.arm_joints, q):
                p.resetJointState(r, idx[j], v, physicsClientId=cid)
            ab = p.getLinkState(r, link[info.arm_base_link], computeForwardKinematics=1, physicsClientId=cid)[4]
            tool = p.getLinkState(r, link[info.tool_link], computeForwardKinematics=1, physicsClientId=cid)[4]
            assert np.allclose(np.subtract(tool, ab), kin.fk(q)[:3, 3], atol=1e-3)
    finally:
        p.disconnect(cid)


@pytest.mark.parametrize("arm", [wx250s(), ur5e()], ids=["wx250s", "ur5e"])
def test_ik_round_trip_random(arm):
    rng = np.random.default_rng(7)
    ok = 0
    for k in range(12):
        lo, hi = np.maximum(arm.lower, -math.pi), np.minimum(arm.upper, math.pi)
        q = lo + (hi - lo) * rng.uniform(0.1, 0.9, arm.dof)
        T = arm.fk(q)
        sol = arm.ik(T, seed=k, attempts=30)
        assert sol is not None, f"no IK for q={q}"
        Ts = arm.fk(sol)
        assert np.linalg.norm(Ts[:3, 3] - T[:3, 3]) < 1e-3
        assert rotation_angle(Ts[:3, :3], T[:3, :3]) < 0.01
        assert arm.within_limits(sol)
        ok += 1
    assert ok == 12


def test_ik_deterministic_and_seeded_from_nearby():
    arm = wx250s()
    q = np.array([0.3, 0.2, -0.3, 0.1, 0.5, -0.2])
    T = arm.fk(q)
    a = arm.ik(T, seed=3)
    b = arm.ik(T, seed=3)
    assert a is not None and np.array_equal(a, b)
    near = arm.ik(T, q + 0.05)
    assert near is not None and np.allclose(near, q, atol=1e-2)


def test_ik_free_approach_rotation_and_unreachable():
    arm = wx250s()
    T = np.eye(4)
    T[:3, 3] = (0.40, 0.05, 0.15)
    # ask for a roll about the approach axis the arm cannot give together with the rest
    Rx = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], dtype=float)
    T2 = T.copy()
    T2[:3, :3] = Rx
    q = arm.ik(T2, free_approach_rotation=True)
    assert q is not None
    Tq = arm.fk(q)
    assert np.linalg.norm(Tq[:3, 3] - T[:3, 3]) < 1e-3
    assert np.dot(Tq[:3, 0], [1, 0, 0]) > math.cos(0.01)
    far = np.eye(4)
    far[:3, 3] = (1.5, 0.0, 0.3)
    assert arm.ik(far) is None
    # within reach by distance, but pointing back at the base from near full extension
    # puts the wrist beyond reach
    back = np.eye(4)
    back[:3, :3] = np.diag([-1.0, -1.0, 1.0])
    back[:3, 3] = (0.55, 0.0, 0.30)
    assert arm.ik(back, attempts=8) is None
