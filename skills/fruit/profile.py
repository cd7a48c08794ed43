"""The robot profile's ``fruit:`` section: what the fruit-picking mission needs to know of
the robot and the plant (where to stand, where to look from, how to detect, fit, grasp
and pull, and where the baskets are). Declared in :mod:`mmexec.skills.profile`, so a
config's mistakes are located errors at load (``FILE:LINE:COL: profile.fruit.key:
...``). It adds the base pose ``fruit_station`` (``fruit.station``) to the named poses
``navigate`` knows.

Frames: ``robot_basket.box`` is in the base frame (``base_footprint``: x forward, z up);
``marker_basket.release`` in the basket marker's frame (x right, y up, z out of the
printed face). Lengths m, angles rad, forces N.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Literal

from mmexec.drivers.interfaces import Pose2D
from mmexec.skills.base import FailureKind, SkillContext, SkillFailure
from mmexec.skills.poses import add_base_pose
from mmexec.skills.profile import declare_section, section, setting

__all__ = ["FruitProfile", "GraspSettings", "MarkerBasket", "RobotBasketSettings", "fruit_profile"]


@dataclass(frozen=True)
class GraspSettings:
    """Thesis Algorithm 1.1 and the motions round it (:mod:`mmexec.skills.manipulation.candidates`)."""

    count: int = setting(50, ge=1, le=500, doc="grasp candidates over theta_range")
    theta_range: tuple[float, float] = setting((-3.14159265, 1.04719755), unit="rad",
                                               doc="theta range of the candidates (thesis: [-pi, pi/3])")
    pick_fraction: float = setting(0.25, ge=0, lt=1, doc="the chosen candidate's place in the reachable list")
    distance: float = setting(0.0, unit="m", ge=0, le=0.1, doc=(
        "barycentre to the tool's grasp point along the approach (0: the pads close across the centre)"))
    pre_grasp: float = setting(0.10, unit="m", gt=0, le=0.3, doc="pre-grasp: this far back along the approach")
    pull: float = setting(0.08, unit="m", gt=0, le=0.3, doc=(
        "after closing, straight back along the approach this far (the magnet lets go)"))
    lift: float = setting(0.05, unit="m", ge=0, le=0.3, doc="then straight up this far, clear of the plant")
    clearance: float = setting(0.01, unit="m", ge=0, le=0.05, doc=(
        "other fruit are planning obstacles this much larger than their fitted radius"))


@dataclass(frozen=True)
class RobotBasketSettings:
    """The basket on the robot: its box (for planning) and the arm pose that drops into it."""

    box: tuple[float, float, float, float, float, float] = setting(
        (-0.205, 0.0, 0.46, 0.20, 0.46, 0.12), unit="m",
        doc="centre [x, y, z] and size [x, y, z] of the basket in the base frame (a planning obstacle)")
    drop_poses: tuple[str, ...] = setting(("drop",), doc=(
        "named arm poses holding the fruit above it, used in turn (spread over the basket, the fruit do not pile up)"))


@dataclass(frozen=True)
class MarkerBasket:
    """The basket tagged with an ArUco marker, found by ``find`` and driven to."""

    marker: int = setting(30, ge=0, le=49, doc="DICT_4X4_50 id on the basket's wall")
    view: tuple[float, float, float] | None = setting(None, unit="m, m, rad", base_pose=True, doc=(
        "base pose [x, y, theta] in map the basket's marker is looked for from (the base pose "
        "'fruit_basket_view'; None: from wherever the robot is)"))
    distance: float = setting(0.55, unit="m", gt=0, le=2, doc="stand-off of the base centre from the marker face")
    release: tuple[float, float, float] = setting((0.0, 0.18, -0.15), unit="m", doc=(
        "release point of the fruit's centre in the marker frame (x right, y up, z out of the face)"))


@dataclass(frozen=True)
class FruitProfile:
    """The ``fruit:`` section (docs/fruit.md)."""

    station: tuple[float, float, float] = setting(unit="m, m, rad", base_pose=True,
                                                  doc="base pose [x, y, theta] in map facing the plant")
    look_poses: tuple[str, ...] = setting(("look",), doc=(
        "named arm poses the wrist camera looks at the plant from, in order (the first that sees fruit is used)"))
    basket: Literal["robot", "marker"] = setting("robot", doc=(
        "drop into the basket on the robot, or drive to the marker-tagged basket (mission param 'basket')"))
    max_depth: float = setting(1.5, unit="m", gt=0, le=5, doc="z_max: farther points and fruit are ignored")
    min_height: float = setting(0.3, unit="m", doc="fruit whose centre is lower (on the floor) are ignored")
    radius_range: tuple[float, float] = setting((0.025, 0.055), unit="m", gt=0, doc="sphere fit radii")
    min_confidence: float = setting(0.5, ge=0, le=1, doc="detections below are ignored")
    attempts: int = setting(2, ge=1, le=5, doc="picks of one fruit before it is skipped as unreachable")
    same_fruit: float = setting(0.03, unit="m", gt=0, doc="two estimates closer than this are one fruit")
    frames: int = setting(2, ge=1, le=10, doc="camera frames per look (the best fit of each fruit is kept)")
    settle: float = setting(0.3, unit="s", ge=0, le=5, doc="wait after reaching a look pose before detecting")
    grasp: GraspSettings = setting(GraspSettings(), doc="grasp candidates and the pick motions")
    robot_basket: RobotBasketSettings = setting(RobotBasketSettings(), doc="the basket on the robot")
    marker_basket: MarkerBasket = setting(MarkerBasket(), doc="the marker-tagged basket")

    def validate(self) -> list[str]:
        errs = []
        lo, hi = self.radius_range
        if not lo <= hi:
            errs.append(f"radius_range: expected [min, max] with min <= max, got {list(self.radius_range)}")
        if not self.look_poses:
            errs.append("look_poses: need at least one named arm pose")
        a, b = self.grasp.theta_range
        if not a <= b:
            errs.append(f"grasp.theta_range: expected [min, max] with min <= max, got {list(self.grasp.theta_range)}")
        return errs


declare_section("fruit", FruitProfile, package="mmexec.skills.fruit",
                doc="the fruit-picking mission: station, look poses, perception, grasp, baskets (docs/fruit.md)")


def fruit_profile(ctx: SkillContext) -> FruitProfile:
    """The bound ``profile.fruit`` section; SkillFailure(PRECONDITION) when it is missing
    or wrong."""
    if not isinstance(ctx.profile, Mapping) or ctx.profile.get("fruit") is None:
        raise SkillFailure(FailureKind.PRECONDITION,
                           "the robot profile has no 'fruit:' section (see docs/fruit.md for its keys)")
    out: FruitProfile = section(ctx.profile, "fruit")
    return out


def _station(ctx: SkillContext) -> Pose2D:
    return Pose2D(*fruit_profile(ctx).station)


def _basket_view(ctx: SkillContext) -> Pose2D:
    prof = fruit_profile(ctx)
    view = prof.marker_basket.view
    if view is None:
        base = ctx.robot.base
        if base is None:
            raise SkillFailure(FailureKind.PRECONDITION, "fruit_basket_view: no fruit.marker_basket.view and no base")
        return base.state().pose
    return Pose2D(*view)


add_base_pose("fruit_station", "fruit", _station)
add_base_pose("fruit_basket_view", "fruit", _basket_view)
