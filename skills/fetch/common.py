"""Shared pieces of the fetch skills: the robot profile's ``fetch:`` section, the world
model keys, status events and small pose helpers.

The fetch package declares its profile section, ``fetch:`` (:class:`FetchProfile`: each
setting with its unit, range and meaning), in :mod:`mmexec.skills.profile`, so a config's
mistakes there are reported when the config loads, as ``FILE:LINE:COL:
profile.fetch.key: message``; a profile set up in code that is wrong fails the first skill
that reads it (PRECONDITION), never with a traceback.

World model (``ctx.world``, shared by every skill of a run, across requests):

===================  ==========================================================
key                  value
===================  ==========================================================
``fetch.markers``    ``{marker id: MarkerEstimate}``: latest map-frame estimate
``fetch.arm``        :class:`mmexec.skills.fetch.arm.ArmWorkspace` (planning scene,
                     kinematics, planner), created on first use
``fetch.costmap``    the inflated navigation map, cached per (grid, radius)
``fetch.search``     :class:`SearchProgress` of the latest search
``fetch.held``       name of the item the robot believes it holds, or absent
===================  ==========================================================
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from mmexec.config.yamlload import InputError, Mark, Problems, mark_of
from mmexec.drivers.interfaces import Pose2D
from mmexec.skills.base import FailureKind, SkillContext, SkillFailure
from mmexec.skills.profile import PROFILE, declare_section, setting

__all__ = [
    "WORLD_ARM",
    "WORLD_COSTMAP",
    "WORLD_HELD",
    "WORLD_MARKERS",
    "WORLD_SEARCH",
    "ArmSettings",
    "DepotSettings",
    "FetchProfile",
    "MarkerEstimate",
    "NavSettings",
    "SearchProgress",
    "arm_status",
    "base_status",
    "fetch_profile",
    "named_base_pose",
    "nav_margin",
    "pose_list",
]

WORLD_MARKERS = "fetch.markers"
WORLD_ARM = "fetch.arm"
WORLD_COSTMAP = "fetch.costmap"
WORLD_SEARCH = "fetch.search"
WORLD_HELD = "fetch.held"



# --------------------------------------------------------------------------- profile


@dataclass(frozen=True)
class NavSettings:
    """Base motion: speed limits and accelerations, extra inflation of the map, goal
    tolerances, pure pursuit lookahead, the default navigation timeout and the goal
    search radius (see each setting's doc)."""

    max_v: float = setting(0.5, unit="m/s", gt=0, doc="linear speed limit")
    max_w: float = setting(1.5, unit="rad/s", gt=0, doc="angular speed limit")
    accel_v: float = setting(0.8, unit="m/s^2", gt=0, doc="linear acceleration limit")
    accel_w: float = setting(3.0, unit="rad/s^2", gt=0, doc="angular acceleration limit")
    margin: float = setting(0.03, unit="m", ge=0, doc="inflation of the map on top of the base's footprint radius")
    goal_tolerance: float = setting(0.04, unit="m", gt=0, doc="position tolerance at the goal")
    heading_tolerance: float = setting(0.04, unit="rad", gt=0, doc="heading tolerance at the goal")
    lookahead: float = setting(0.35, unit="m", gt=0, doc="pure pursuit lookahead")
    timeout: float = setting(90.0, unit="clock s", gt=0, doc="default navigation timeout")
    goal_search: float = setting(0.3, unit="m", ge=0, doc=(
        "a goal that an obstacle covers (in the inflated map) is moved to the nearest free point within "
        "this distance, like a global planner's goal tolerance (0: fail instead)"))


@dataclass(frozen=True)
class ArmSettings:
    """Arm planning: the planning model, the OMPL planner's settings, speed scaling, and
    the named poses (keys of the profile's ``named_poses``) the skills use in each role.
    Planning runs on a worker thread; on a wall clock each tick waits at most
    ``plan_slice`` [wall s] for it (keep it well below the tick period), then yields; on
    a stepped clock (sim, mock) the tick waits for the plan, which costs exactly one tick
    of clock time."""

    model: Literal["locobot_wx250s", "ur5e_robotiq"] = setting(
        "locobot_wx250s", doc="sim model name whose URDF is the planning model")
    tcp_offset: float = setting(0.155, unit="m", ge=0, doc="UR tool: flange to the closed-grasp point")
    algorithm: Literal["rrtconnect", "rrtstar"] = setting("rrtconnect", doc="OMPL planner")
    time_limit: float = setting(1.0, unit="s", gt=0, doc="planning time per attempt")
    attempts: int = setting(3, ge=1, doc="planning attempts")
    velocity_scale: float = setting(0.8, gt=0, le=1, doc="fraction of the joint velocity limits")
    acceleration_scale: float = setting(0.8, gt=0, le=1, doc="fraction of the joint acceleration limits")
    stow: str = setting("sleep", refers_to="named_poses", doc="named pose to stow the arm in while driving")
    carry: str = setting("sleep", refers_to="named_poses", doc="named pose to carry an item in")
    look: str | None = setting(None, refers_to="named_poses",
                               doc="named pose to look with an arm-mounted camera (None: camera not on the arm)")
    reach: str | None = setting(None, refers_to="named_poses", doc=(
        "posture that seeds IK for pick and place poses, its yaw joint turned towards the target "
        "(None: the current posture only)"))
    plan_slice: float = setting(0.015, unit="wall s", ge=0, le=0.1, doc="longest a tick waits for the planner on a wall clock")


@dataclass(frozen=True)
class DepotSettings:
    """The depot: where the base stops to place, and where the held item is released."""

    base: tuple[float, float, float] = setting(unit="m, m, rad", base_pose=True,
                                               doc="base pose [x, y, theta] in map where the base stops to place")
    place: tuple[float, float, float] = setting(unit="m", doc="point [x, y, z] in map where the held item's centre is released")


@dataclass(frozen=True)
class FetchProfile:
    """The ``fetch:`` section of a robot profile (see docs/fetch.md and each setting's
    doc). Lengths in m, angles in rad unless the name says ``deg``; marker-frame offsets
    have x right, y up, z out of the marker face."""

    depot: DepotSettings = setting(doc="where the base stops to place and where the item is released")
    search_locations: list[tuple[float, float, float]] = setting(
        [], unit="m, m, rad", base_pose=True, doc="base poses [x, y, theta] in map visited in order by search")
    approach_distances: list[float] = setting(
        [0.35, 0.45, 0.55], unit="m", gt=0,
        doc="stand-off distances from the marker face, tried in order (the base recovery indexes them)")
    item_size: tuple[float, float, float] = setting((0.06, 0.06, 0.06), unit="m", gt=0,
                                                    doc="box [x, y, z] added to the planning scene")
    marker_length: float = setting(0.045, unit="m", gt=0, doc="side of the marker's black square")
    marker_dictionary: str = setting("DICT_4X4_50", doc="ArUco dictionary")
    search_step_deg: float = setting(30.0, unit="deg", ge=1, le=180, doc="turn between two views of a search")
    settle_time: float = setting(0.2, unit="s", ge=0, doc="wait after a turn before looking")
    detect_frames: int = setting(3, ge=1, doc="frames averaged per detection")
    grasp_depth: float = setting(0.03, unit="m", ge=0, doc="how far behind the marker face the grasp point lies")
    grasp_height: float = setting(0.0, unit="m", doc=(
        "how far above the marker centre (along the marker's y, up) the pick and place poses lie: a gripper "
        "body thicker than the box is tall grasps the box's upper part so the body clears the board under it"))
    refine_at: float = setting(0.8, unit="m", gt=0, doc=(
        "the base's stand-off from the marker face where approach looks again when the estimate was seen "
        "from afar (a wrist camera ahead of the base needs it farther than a head camera does)"))
    redetect_at_standoff: bool = setting(False, doc=(
        "approach looks at the marker once more from the stand-off pose it reached and keeps that estimate "
        "for the pick"))
    pre_grasp: tuple[float, float, float] = setting((0.0, 0.0, 0.10), unit="m", doc="pre-grasp offset, marker frame")
    retract: tuple[float, float, float] = setting((0.0, 0.10, 0.10), unit="m", doc="retreat after a grasp, marker frame")
    place_retract: tuple[float, float, float] = setting((0.0, 0.0, 0.10), unit="m",
                                                        doc="retreat after a release, place frame")
    grasp_force: float = setting(20.0, unit="N", gt=0, doc="gripper force")
    back_off: float = setting(0.25, unit="m", ge=0, doc="how far the base backs away after a pick")
    min_held_width: float = setting(0.01, unit="m", ge=0, doc="a closed gripper narrower than this holds nothing")
    nav: NavSettings = setting(NavSettings(), doc="base motion")
    arm: ArmSettings = setting(ArmSettings(), doc="arm planning")

    def validate(self) -> list[str]:
        """Checks that relate several settings (single-value ranges are declared)."""
        out = []
        if not self.approach_distances:
            out.append("approach_distances: expected a non-empty list of distances > 0 m")
        if not abs(self.grasp_height) < self.item_size[2] / 2:
            out.append(f"grasp_height: expected less than half the item's height ({self.item_size[2] / 2:g} m) "
                       f"from its centre, got {self.grasp_height:g} m")
        return out


declare_section("fetch", FetchProfile, package="mmexec.skills.fetch",
                doc="the fetch mission's settings (docs/fetch.md)")

_PROFILE_CACHE: dict[int, tuple[Any, FetchProfile]] = {}


def fetch_profile(ctx: SkillContext) -> FetchProfile:
    """The bound ``profile.fetch`` section; SkillFailure(PRECONDITION) naming the file
    position when it is missing or wrong (a config checked at load cannot be wrong here;
    a profile set up in code, as in tests, can)."""
    raw = ctx.profile.get("fetch") if isinstance(ctx.profile, Mapping) else None
    if raw is None:
        raise SkillFailure(FailureKind.PRECONDITION,
                           "the robot profile has no 'fetch:' section (see docs/fetch.md for its keys)")
    cached = _PROFILE_CACHE.get(id(raw))
    if cached is not None and cached[0] is raw:
        return cached[1]
    problems = Problems()
    out = PROFILE.bind_section("fetch", raw, mark_of(raw, Mark("<profile>", 1, 1)), problems)
    if problems:
        raise SkillFailure(FailureKind.PRECONDITION, str(problems[0]))
    assert isinstance(out, FetchProfile)
    _PROFILE_CACHE[id(raw)] = (raw, out)
    return out


def check_profile(profile: Mapping[str, Any]) -> None:
    """Raise InputError with every problem of ``profile['fetch']`` (for config checks)."""
    raw = profile.get("fetch")
    if raw is None:
        raise InputError.at(mark_of(profile, Mark("<profile>", 1, 1)), "profile: missing 'fetch:' section")
    problems = Problems()
    PROFILE.bind_section("fetch", raw, mark_of(raw, Mark("<profile>", 1, 1)), problems)
    problems.raise_if_any()


def nav_margin(profile: Mapping[str, Any]) -> float:
    """The margin [m] navigation adds to the base's footprint radius when it inflates the
    map: ``fetch.nav.margin``, or its default when the profile has no (valid) fetch
    section."""
    raw = profile.get("fetch")
    if raw is not None:
        out = PROFILE.bind_section("fetch", raw, mark_of(raw, Mark("<profile>", 1, 1)), Problems())
        if isinstance(out, FetchProfile):
            return out.nav.margin
    return NavSettings().margin


def pose_list(value: Any, what: str) -> Pose2D:
    """``[x, y, theta]`` -> Pose2D, or SkillFailure(PRECONDITION) naming ``what``."""
    if (not isinstance(value, (list, tuple)) or len(value) != 3
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)):
        raise SkillFailure(FailureKind.PRECONDITION, f"{what}: expected [x, y, theta] in map, got {value!r}")
    return Pose2D(float(value[0]), float(value[1]), float(value[2]))


def named_base_pose(ctx: SkillContext, name: str) -> Pose2D:
    """A base pose by name: ``home`` (profile ``home``), ``depot`` (profile
    ``fetch.depot.base``) or a key of the profile's ``places``."""
    prof = ctx.profile
    if name == "home" and "home" in prof:
        return pose_list(prof["home"], "profile.home")
    if name == "depot" and "fetch" in prof:
        return Pose2D(*fetch_profile(ctx).depot.base)
    places = prof.get("places") or {}
    if isinstance(places, Mapping) and name in places:
        return pose_list(places[name], f"profile.places.{name}")
    known = [k for k in ("home",) if k in prof] + (["depot"] if "fetch" in prof else [])
    known += sorted(places) if isinstance(places, Mapping) else []
    raise SkillFailure(FailureKind.PRECONDITION,
                       f"no base pose named {name!r} in the robot profile (known: {', '.join(known) or 'none'})")


# --------------------------------------------------------------------------- world model


@dataclass(frozen=True)
class MarkerEstimate:
    """A marker's pose ``T_map_marker`` (4x4, map frame, OpenCV ArUco axes: z out of the
    face), from ``samples`` observations, at clock time ``stamp`` [s], seen from
    ``distance`` [m] (camera to marker, the closest of the samples)."""

    marker: int
    T_map_marker: np.ndarray
    samples: int
    stamp: float
    distance: float

    def as_list(self) -> list[float]:
        """[x, y, z, yaw] of the marker in map [m, rad] (yaw of its outward normal)."""
        T = self.T_map_marker
        return [float(T[0, 3]), float(T[1, 3]), float(T[2, 3]), math.atan2(float(T[1, 2]), float(T[0, 2]))]


@dataclass
class SearchProgress:
    """What the latest search did: views captured, locations visited, where it found the
    marker (map pose [x, y, theta]) or None."""

    marker: int
    views: int = 0
    locations_visited: int = 0
    found_at: tuple[float, float, float] | None = None


def markers(ctx: SkillContext) -> dict[int, MarkerEstimate]:
    """The world model's marker estimates (created on first use)."""
    return ctx.world.setdefault(WORLD_MARKERS, {})


# --------------------------------------------------------------------------- events


def base_status(ctx: SkillContext, status: str, **fields: Any) -> None:
    """Emit the seed's base state: ``to_goal``, ``goal_ok``, ``goal_fail`` or ``idle``."""
    ctx.emit("base_status", status=status, node=ctx.node_path, **fields)


def arm_status(ctx: SkillContext, status: str, **fields: Any) -> None:
    """Emit the seed's arm state: ``running``, ``success``, ``fail`` or ``idle``."""
    ctx.emit("arm_status", status=status, node=ctx.node_path, **fields)
