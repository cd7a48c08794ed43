"""One source of kinematic facts: the planning kinematics and the fakes read the drivers'
model modules, and the two UR forward kinematics (DH in the driver, PoE for planning)
agree, as do the WX250s joint limits in the driver, the planner and the fake servos."""

from __future__ import annotations

import numpy as np

from mmexec.drivers.dynamixel import model as wxmodel
from mmexec.drivers.dynamixel.control_table import pulses_to_rad
from mmexec.drivers.fakes.dynamixel import wx250s_servos
from mmexec.drivers.ur import model as urmodel
from mmexec.skills.manipulation import kinematics


def test_planner_uses_the_driver_ur_table() -> None:
    assert kinematics.UR5E_DH is urmodel.DH["ur5e"]
    kin = kinematics.ur5e(tcp_offset=0.0)
    assert kin.joint_names == urmodel.JOINT_NAMES
    assert [(lim.lower, lim.upper, lim.velocity, lim.effort) for lim in kin.limits] == [
        (lim.lower, lim.upper, lim.velocity, lim.effort) for lim in urmodel.joint_limits("ur5e")
    ]


def test_ur_dh_and_poe_forward_kinematics_agree() -> None:
    kin = kinematics.ur5e(tcp_offset=0.0)
    rng = np.random.default_rng(3)
    for _ in range(20):
        q = rng.uniform(-np.pi, np.pi, 6)
        dh = urmodel.T_BASELINK_BASE @ urmodel.forward_kinematics(q, "ur5e")
        assert np.allclose(kin.fk(q), dh, atol=1e-9), q


def test_wx250s_limits_are_the_driver_ones_everywhere() -> None:
    kin = kinematics.wx250s(acceleration=4.0)
    assert [(lim.name, lim.lower, lim.upper, lim.velocity, lim.effort) for lim in kin.limits] == [
        (j.name, j.lower, j.upper, j.velocity, j.effort) for j in wxmodel.ARM_JOINTS
    ]
    assert all(lim.acceleration == 4.0 for lim in kin.limits)
    by_id = {s.id: s for s in wx250s_servos(locobot=True, configured=True)}
    for j in wxmodel.ARM_JOINTS + wxmodel.PAN_TILT:
        for dxl_id in (j.id,) + ((j.shadow,) if j.shadow is not None else ()):
            s = by_id[dxl_id]
            assert (s.get("min_position_limit"), s.get("max_position_limit")) == (j.min_pulses, j.max_pulses)
        # the URDF range lies within the register range (2048 pulses = 0 rad, 1 pulse =
        # 1.5 mrad; Drive Mode's reverse bit makes the servo count in the joint's direction)
        lo, hi = pulses_to_rad(j.min_pulses), pulses_to_rad(j.max_pulses)
        assert lo - 2e-3 <= j.lower and j.upper <= hi + 2e-3, j.name
