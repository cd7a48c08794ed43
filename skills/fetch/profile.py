"""The robot profile's ``fetch:`` section: what is specific to fetching a tagged box (the
item's size and where to grasp it behind its marker, the seed's grasp offsets) and to
delivering it (the depot).

The fetch package declares the section (:class:`FetchProfile`: each setting with its
unit, range and meaning) in :mod:`mmexec.skills.profile`, so a config's mistakes there
are reported when the config loads, as ``FILE:LINE:COL: profile.fetch.key: message``; a
profile set up in code that is wrong fails the first skill that reads it (PRECONDITION),
never with a traceback. It also adds the base pose ``depot`` (``fetch.depot.base``) to
the named poses ``navigate`` knows (:func:`mmexec.skills.poses.add_base_pose`).

The general settings the fetch mission uses live in the general skills' sections:
``nav`` (base motion, approach distances), ``arm`` (planning, role poses, gripper),
``camera`` (markers), ``search`` (locations, step). A config that still writes them
under ``fetch:`` gets a located error naming the new place (:data:`MOVED`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from mmexec.drivers.interfaces import Pose2D
from mmexec.skills.base import FailureKind, SkillContext, SkillFailure
from mmexec.skills.poses import add_base_pose
from mmexec.skills.profile import PROFILE, declare_section, section, setting

__all__ = ["MOVED", "DepotSettings", "FetchProfile", "fetch_profile"]


@dataclass(frozen=True)
class DepotSettings:
    """The depot: where the base stops to place, and where the held item is released."""

    base: tuple[float, float, float] = setting(unit="m, m, rad", base_pose=True,
                                               doc="base pose [x, y, theta] in map where the base stops to place")
    place: tuple[float, float, float] = setting(unit="m", doc="point [x, y, z] in map where the held item's centre is released")


@dataclass(frozen=True)
class FetchProfile:
    """The ``fetch:`` section of a robot profile (see docs/fetch.md and each setting's
    doc). Lengths in m; marker-frame offsets have x right, y up, z out of the marker face."""

    depot: DepotSettings = setting(doc="where the base stops to place and where the item is released")
    item_size: tuple[float, float, float] = setting((0.06, 0.06, 0.06), unit="m", gt=0,
                                                    doc="box [x, y, z] added to the planning scene")
    grasp_depth: float = setting(0.03, unit="m", ge=0, doc="how far behind the marker face the grasp point lies")
    grasp_height: float = setting(0.0, unit="m", doc=(
        "how far above the marker centre (along the marker's y, up) the pick and place poses lie: a gripper "
        "body thicker than the box is tall grasps the box's upper part so the body clears the board under it"))
    pre_grasp: tuple[float, float, float] = setting((0.0, 0.0, 0.10), unit="m", doc="pre-grasp offset, marker frame")
    retract: tuple[float, float, float] = setting((0.0, 0.10, 0.10), unit="m", doc="retreat after a grasp, marker frame")
    place_retract: tuple[float, float, float] = setting((0.0, 0.0, 0.10), unit="m",
                                                        doc="retreat after a release, place frame")
    back_off: float = setting(0.25, unit="m", ge=0, doc="how far the base backs away after a pick")

    def validate(self) -> list[str]:
        """Checks that relate several settings (single-value ranges are declared)."""
        if not abs(self.grasp_height) < self.item_size[2] / 2:
            return [(f"grasp_height: expected less than half the item's height ({self.item_size[2] / 2:g} m) "
                     f"from its centre, got {self.grasp_height:g} m")]
        return []


declare_section("fetch", FetchProfile, package="mmexec.skills.fetch",
                doc="the fetch mission's settings: the item, its grasp, the depot (docs/fetch.md)")

#: Settings that left ``fetch:`` for the general skills' sections: old key -> new place.
MOVED: dict[str, str] = {
    "fetch.nav": "nav",
    "fetch.arm": "arm",
    "fetch.approach_distances": "nav.approach_distances",
    "fetch.refine_at": "nav.refine_at",
    "fetch.redetect_at_standoff": "nav.redetect_at_standoff",
    "fetch.grasp_force": "arm.grasp_force",
    "fetch.min_held_width": "arm.min_held_width",
    "fetch.marker_length": "camera.marker_length",
    "fetch.marker_dictionary": "camera.marker_dictionary",
    "fetch.detect_frames": "camera.detect_frames",
    "fetch.search_locations": "search.locations",
    "fetch.search_step_deg": "search.step_deg",
    "fetch.settle_time": "search.settle_time",
}
for _old, _new in MOVED.items():
    PROFILE.move(_old, _new)


def fetch_profile(ctx: SkillContext) -> FetchProfile:
    """The bound ``profile.fetch`` section; SkillFailure(PRECONDITION) naming the file
    position when it is missing or wrong (a config checked at load cannot be wrong here;
    a profile set up in code, as in tests, can)."""
    if not isinstance(ctx.profile, Mapping) or ctx.profile.get("fetch") is None:
        raise SkillFailure(FailureKind.PRECONDITION,
                           "the robot profile has no 'fetch:' section (see docs/fetch.md for its keys)")
    out: FetchProfile = section(ctx.profile, "fetch")
    return out


def _depot(ctx: SkillContext) -> Pose2D:
    return Pose2D(*fetch_profile(ctx).depot.base)


add_base_pose("depot", "fetch", _depot)
