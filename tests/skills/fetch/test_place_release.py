"""How place releases an elongated item (skills/fetch/arm.py): the pose choice alone, on
the UR5e's kinematics (no robot, no physics). The UR carry pose holds a top-grasped tool
lying across vertically closing fingers; the fetch's nominal place pose (approach
horizontal, fingers closing horizontally) would stand it on end, and a tool held by one
end then hangs from the open fingers by its wider end. Place releases such an item from
above instead, lying as it was carried, its centre where the nominal pose releases it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mmexec.skills.fetch.arm import _place_frame, _stood_up, _top_down
from mmexec.skills.manipulation import place_poses
from mmexec.skills.manipulation.kinematics import ur5e

CARRY = [0.0, -2.2, 2.3, -3.24, -1.5708, 0.0]  # config/ur5e_objects_sim.yaml named pose carry
SCREWDRIVER = (0.19, 0.04, 0.04)
BOX = (0.05, 0.05, 0.08)
CAN_AS_HELD = (0.04, 0.04, 0.08)  # the cylinder's box as held (HELD_CLEARANCE off each side)


def _held_as_top_grasped() -> np.ndarray:
    """T_tool_item of an item picked from above: its centre 2 cm beyond the TCP along the
    approach (z), its first (longest) side along the tool's x, across the fingers (y)."""
    T = np.eye(4)
    T[2, 3] = 0.02
    return T


def _nominal(kin):
    T_place = _place_frame((0.6, 0.0, 0.30), (0.0, 0.0))  # 0.6 m ahead of the arm base, 0.3 m up
    return T_place, place_poses(T_place, kin.approach_axis, retract=(0.0, 0.12, 0.0))


def test_the_nominal_place_would_stand_a_top_grasped_tool_on_end_but_not_a_box():
    kin = ur5e()
    T_item = _held_as_top_grasped()
    _, nominal = _nominal(kin)
    # carried lying: the long side horizontal at the carry pose
    assert abs((kin.fk(CARRY)[:3, :3] @ T_item[:3, 0])[2]) < 0.05
    assert _stood_up(SCREWDRIVER, T_item, nominal.place)
    assert not _stood_up(BOX, T_item, nominal.place)  # not elongated: the seed's release
    assert not _stood_up(CAN_AS_HELD, T_item, nominal.place)
    # a tool the nominal pose keeps lying is released as before
    T_lying = np.eye(4)
    T_lying[:3, :3] = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])  # long side along tool y
    assert not _stood_up(SCREWDRIVER, T_lying, nominal.place)


def test_the_release_from_above_keeps_the_tool_lying_with_its_centre_at_the_place_point():
    kin = ur5e()
    T_item = _held_as_top_grasped()
    T_place, nominal = _nominal(kin)
    lift = nominal.retract[:3, 3] - nominal.place[:3, 3]
    poses = _top_down(kin.fk(CARRY), T_item, T_place[:3, 3], lift, kin.approach_axis)
    assert len(poses) == 4
    yaws = []
    for p in poses:
        R = p.place[:3, :3]
        assert R @ R.T == pytest.approx(np.eye(3), abs=1e-9)
        assert R[:, kin.approach_axis] == pytest.approx([0.0, 0.0, -1.0], abs=1e-9)  # pointing down
        assert abs(R[2, 1]) < 1e-9  # the fingers (tool y) close horizontally: opening drops the item
        long_side = R @ T_item[:3, 0]
        assert abs(long_side[2]) < 1e-9  # lying
        assert (p.place @ T_item)[:3, 3] == pytest.approx(T_place[:3, 3], abs=1e-9)  # centre released there
        assert p.retract[:3, 3] - p.place[:3, 3] == pytest.approx([0.0, 0.0, 0.12], abs=1e-9)  # straight up
        assert p.retract[:3, :3] == pytest.approx(R, abs=1e-12)
        yaws.append(math.atan2(long_side[1], long_side[0]))
    # the first keeps the long side's carried direction (the tool only tilts), then quarter turns
    carried = kin.fk(CARRY)[:3, :3] @ T_item[:3, 0]
    assert yaws[0] == pytest.approx(math.atan2(carried[1], carried[0]), abs=1e-6)
    turns = sorted(round(math.degrees((y - yaws[0] + math.pi) % (2 * math.pi) - math.pi)) for y in yaws)
    assert turns == [-90, 0, 90, 180] or turns == [-180, -90, 0, 90]
    # the first is within the UR5e's reach
    assert kin.ik(poses[0].place, CARRY) is not None


def test_only_an_item_resting_on_the_lower_finger_is_released_from_above():
    """The UR carry closes the fingers vertically (the tool lies on the lower one): released
    from above. The LoCoBot's carry pinches horizontally, as its nominal place pose does:
    the nominal release, whatever the item."""
    from mmexec.skills.fetch.arm import _resting_on_a_finger
    from mmexec.skills.manipulation.kinematics import wx250s

    assert _resting_on_a_finger(ur5e().fk(CARRY))
    assert not _resting_on_a_finger(wx250s(locobot=True).fk([0.0, -0.2, 0.6, 0.0, 0.5, 0.0]))  # locobot carry
