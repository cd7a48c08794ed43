"""Forward kinematics of the simulated models against the official parameters."""

from __future__ import annotations

import math

import numpy as np
import pybullet as p
import pytest

from mmexec.drivers.descriptions import DESCRIPTIONS
from mmexec.sim.models import MODEL_INFO, urdf_path
from mmexec.sim.models.urdfgen import urdf_model


@pytest.fixture(scope="module")
def client():
    cid = p.connect(p.DIRECT)
    yield cid
    p.disconnect(cid)


def _load(cid: int, name: str) -> tuple[int, dict[str, int], dict[str, int]]:
    body = p.loadURDF(str(urdf_path(name)), useFixedBase=True, physicsClientId=cid)
    links, joints = {}, {}
    for i in range(p.getNumJoints(body, physicsClientId=cid)):
        info = p.getJointInfo(body, i, physicsClientId=cid)
        links[info[12].decode()] = i
        joints[info[1].decode()] = i
    return body, links, joints


def _T(cid: int, body: int, link: int) -> np.ndarray:
    s = p.getLinkState(body, link, computeForwardKinematics=True, physicsClientId=cid)
    T = np.eye(4)
    T[:3, :3] = np.array(p.getMatrixFromQuaternion(s[5])).reshape(3, 3)
    T[:3, 3] = s[4]
    return T


def _set(cid: int, body: int, joints: dict[str, int], names, q) -> None:
    for n, v in zip(names, q):
        p.resetJointState(body, joints[n], float(v), physicsClientId=cid)


def _skew(w):
    return np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])


def _exp(S, th):
    w, v = np.array(S[:3], float), np.array(S[3:], float)
    W = _skew(w)
    R = np.eye(3) + math.sin(th) * W + (1 - math.cos(th)) * W @ W
    G = np.eye(3) * th + (1 - math.cos(th)) * W + (th - math.sin(th)) * W @ W
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, G @ v
    return T


def wx250s_poe(q, h: float = 0.005825) -> np.ndarray:
    """Interbotix PoE (space frame) for the WX250s, LoCoBot heights (h subtracted)."""
    z1, z2 = 0.11065 - h, 0.36065 - h
    Slist = [
        (0, 0, 1, 0, 0, 0),
        (0, 1, 0, -z1, 0, 0),
        (0, 1, 0, -z2, 0, 0.04975),
        (1, 0, 0, 0, z2, 0),
        (0, 1, 0, -z2, 0, 0.29975),
        (1, 0, 0, 0, z2, 0),
    ]
    M = np.eye(4)
    M[:3, 3] = (0.458325, 0.0, z2)
    T = np.eye(4)
    for S, th in zip(Slist, q):
        T = T @ _exp(S, th)
    return T @ M


#: the official DH tables (docs/robots.md 2.1) of the UR platforms' arms: d, a [m] per joint
UR_DH = {"ur5e_robotiq": ((0.1625, 0, 0, 0.1333, 0.0997, 0.0996), (0, -0.425, -0.3922, 0, 0, 0)),
         "ur3e_robotiq": ((0.15185, 0, 0, 0.13105, 0.08535, 0.0921), (0, -0.24355, -0.2132, 0, 0, 0))}
#: tool0 at the zero configuration in base_link (docs/robots.md 2.1)
UR_ZERO = {"ur5e_robotiq": (0.8172, 0.2329, 0.0628), "ur3e_robotiq": (0.45675, 0.22315, 0.0665)}
#: max joint speeds [rad/s] (docs/robots.md 2.2); the UR3e's wrist 3 has no position limit
UR_SPEED = {"ur5e_robotiq": (math.pi,) * 6, "ur3e_robotiq": (math.pi,) * 3 + (2 * math.pi,) * 3}
UR_CONTINUOUS = {"ur5e_robotiq": (), "ur3e_robotiq": ("wrist_3_joint",)}


def ur_dh(q, model: str = "ur5e_robotiq") -> np.ndarray:
    """Standard DH of a UR arm (official table): tool0 in the controller's ``base`` frame."""
    d, a = UR_DH[model]
    alpha = (math.pi / 2, 0, 0, math.pi / 2, -math.pi / 2, 0)
    T = np.eye(4)
    for i in range(6):
        ct, st = math.cos(q[i]), math.sin(q[i])
        ca, sa = math.cos(alpha[i]), math.sin(alpha[i])
        T = T @ np.array([[ct, -st * ca, st * sa, a[i] * ct], [st, ct * ca, -ct * sa, a[i] * st],
                          [0, sa, ca, d[i]], [0, 0, 0, 1]])
    return T


def test_committed_urdf_matches_generator():
    for description in DESCRIPTIONS.values():
        model = urdf_model(description)
        assert urdf_path(model.name).read_text() == model.to_xml(), f"re-run urdfgen for {model.name}"


def test_unknown_model_name_lists_known():
    with pytest.raises(KeyError, match="locobot_wx250s"):
        urdf_path("locobot_wx200")


def test_wx250s_zero_pose_in_arm_base(client):
    info = MODEL_INFO["locobot_wx250s"]
    body, links, _joints = _load(client, info.name)
    T = np.linalg.inv(_T(client, body, links[info.arm_base_link])) @ _T(client, body, links[info.tool_link])
    assert np.allclose(T[:3, 3], (0.458325, 0.0, 0.354825), atol=1e-3)
    assert np.allclose(T[:3, :3], np.eye(3), atol=1e-6)
    foot = _T(client, body, links[info.tool_link])[:3, 3]  # root link = base_footprint at origin
    assert np.allclose(foot, (0.555602, 0.0, 0.462775), atol=1e-3)


def test_wx250s_random_configurations_match_poe(client):
    info = MODEL_INFO["locobot_wx250s"]
    body, links, joints = _load(client, info.name)
    rng = np.random.default_rng(4)
    lims = [p.getJointInfo(body, joints[n], physicsClientId=client)[8:10] for n in info.arm_joints]
    for _ in range(25):
        q = [rng.uniform(lo, hi) for lo, hi in lims]
        _set(client, body, joints, info.arm_joints, q)
        T = np.linalg.inv(_T(client, body, links[info.arm_base_link])) @ _T(client, body, links[info.tool_link])
        R = wx250s_poe(q)
        assert np.linalg.norm(T[:3, 3] - R[:3, 3]) < 1e-3
        assert np.allclose(T[:3, :3], R[:3, :3], atol=1e-4)


def test_wx250s_limits_are_the_real_ones(client):
    body, _, joints = _load(client, "locobot_wx250s")
    expect = {"waist": (-(math.pi - 1e-5), math.pi - 1e-5), "shoulder": (-1.88496, 1.98968),
              "elbow": (-2.14675, 1.60570), "wrist_angle": (-1.74533, 2.14675),
              "left_finger": (0.015, 0.037), "right_finger": (-0.037, -0.015), "tilt": (-math.pi / 2, 1.309)}
    for name, (lo, hi) in expect.items():
        info = p.getJointInfo(body, joints[name], physicsClientId=client)
        assert info[8:10] == pytest.approx((lo, hi), abs=1e-6), name
        if name in MODEL_INFO["locobot_wx250s"].arm_joints:
            assert info[11] == pytest.approx(math.pi)


def test_locobot_static_frames(client):
    info = MODEL_INFO["locobot_wx250s"]
    body, links, _ = _load(client, info.name)
    expect = {"plate_link": (0, 0, 0.09845), "pan_link": (0.023231, -0.000044, 0.54268),
              "tilt_link": (0.048265, -0.000044, 0.56168), "camera_link": (0.101445, 0.017456, 0.561689),
              "laser_frame_link": (-0.097997, -0.000044, 0.63693)}
    for name, xyz in expect.items():
        assert np.allclose(_T(client, body, links[name])[:3, 3], xyz, atol=1e-4), name
    lid = _T(client, body, links["laser_frame_link"])
    assert np.allclose(lid[:3, 0], (-1, 0, 0), atol=1e-6)  # yawed pi
    opt = _T(client, body, links[info.camera_optical_link])
    assert np.allclose(opt[:3, 2], (1, 0, 0), atol=1e-6) and np.allclose(opt[:3, 0], (0, -1, 0), atol=1e-6)


@pytest.mark.parametrize("model", list(UR_DH))
def test_ur_zero_pose_tool0(client, model: str):
    info = MODEL_INFO[model]
    body, links, _ = _load(client, info.name)
    T = np.linalg.inv(_T(client, body, links["base_link"])) @ _T(client, body, links["tool0"])
    assert np.allclose(T[:3, 3], UR_ZERO[model], atol=1e-3)
    assert np.allclose(T[:3, 2], (0, 1, 0), atol=1e-6)  # tool z along +y of base_link


@pytest.mark.parametrize("model", list(UR_DH))
def test_ur_random_configurations_match_dh(client, model: str):
    info = MODEL_INFO[model]
    body, links, joints = _load(client, info.name)
    Rz = np.diag([-1.0, -1.0, 1.0, 1.0])  # base_link -> controller base (pi about z)
    rng = np.random.default_rng(5)
    for _ in range(25):
        q = rng.uniform(-math.pi, math.pi, size=6)
        _set(client, body, joints, info.arm_joints, q)
        T = np.linalg.inv(_T(client, body, links["base_link"])) @ _T(client, body, links["tool0"])
        R = Rz @ ur_dh(q, model)
        assert np.linalg.norm(T[:3, 3] - R[:3, 3]) < 1e-3
        assert np.allclose(T[:3, :3], R[:3, :3], atol=1e-4)


@pytest.mark.parametrize("model", list(UR_DH))
def test_ur_limits_and_gripper(client, model: str):
    info = MODEL_INFO[model]
    body, links, joints = _load(client, info.name)
    for n, speed in zip(info.arm_joints, UR_SPEED[model]):
        ji = p.getJointInfo(body, joints[n], physicsClientId=client)
        bound = math.pi if n == "elbow_joint" else 2 * math.pi
        if n in UR_CONTINUOUS[model]:
            assert ji[2] == p.JOINT_REVOLUTE and ji[8] > ji[9], n  # pybullet's continuous joint: 0 > -1
        else:
            assert ji[8:10] == pytest.approx((-bound, bound)), n
        assert ji[11] == pytest.approx(speed), n
    # open: pad inner faces 85 mm apart; closed: touching; coupling 0.011 on the flange
    for width in (0.085, 0.04, 0.0):
        _set(client, body, joints, info.gripper_joints, info.width_to_q(width))
        l, r = (_T(client, body, links[k]) for k in info.finger_links)
        gap = np.linalg.inv(_T(client, body, links["robotiq_base_link"])) @ np.stack([l[:, 3], r[:, 3]], 1)
        assert gap[1, 0] - gap[1, 1] == pytest.approx(width, abs=1e-6)
    base = np.linalg.inv(_T(client, body, links["tool0"])) @ _T(client, body, links["robotiq_base_link"])
    assert np.allclose(base[:3, 3], (0, 0, 0.011), atol=1e-9)


def test_locobot_gripper_width_mapping(client):
    info = MODEL_INFO["locobot_wx250s"]
    body, links, joints = _load(client, info.name)
    for width in (0.030, 0.05, 0.074):
        _set(client, body, joints, info.gripper_joints, info.width_to_q(width))
        l, r = (_T(client, body, links[k]) for k in info.finger_links)
        assert np.linalg.norm(l[:3, 3] - r[:3, 3]) == pytest.approx(width, abs=1e-6)
        assert info.q_to_width(*info.width_to_q(width)) == pytest.approx(width)
