"""Shared pieces of the fetch skills: the robot profile's ``fetch:`` section, the world
model keys, status events and small pose helpers.

The profile section is bound through :mod:`mmexec.config.yamlload`, so a mistake in a
config file fails the first skill that reads it with ``FILE:LINE:COL: profile.fetch.key:
message`` (a PRECONDITION failure), never a traceback.

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
from collections.abc import Generator, Mapping
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from mmexec.config.yamlload import InputError, Mark, Problems, bind, mark_of
from mmexec.drivers.interfaces import Base, Pose2D
from mmexec.skills.base import FailureKind, SkillCancelled, SkillContext, SkillFailure

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
    "brake",
    "fetch_profile",
    "named_base_pose",
    "pose_list",
]

WORLD_MARKERS = "fetch.markers"
WORLD_ARM = "fetch.arm"
WORLD_COSTMAP = "fetch.costmap"
WORLD_SEARCH = "fetch.search"
WORLD_HELD = "fetch.held"

#: Below these speeds [m/s, rad/s] the base counts as stopped.
STOPPED_V = 1e-3
STOPPED_W = 1e-3


# --------------------------------------------------------------------------- profile


@dataclass(frozen=True)
class NavSettings:
    """Base motion: speed limits [m/s, rad/s], accelerations [m/s^2, rad/s^2], extra
    inflation ``margin`` [m] on top of the base radius, goal tolerances [m, rad], pure
    pursuit ``lookahead`` [m], the default navigation ``timeout`` [clock s] and
    ``goal_search`` [m]: a goal that an obstacle covers (in the inflated map) is moved to
    the nearest free point within this distance, like a global planner's goal tolerance
    (0: fail instead)."""

    max_v: float = 0.5
    max_w: float = 1.5
    accel_v: float = 0.8
    accel_w: float = 3.0
    margin: float = 0.03
    goal_tolerance: float = 0.04
    heading_tolerance: float = 0.04
    lookahead: float = 0.35
    timeout: float = 90.0
    goal_search: float = 0.3

    def validate(self) -> list[str]:
        bad = [n for n in ("max_v", "max_w", "accel_v", "accel_w", "goal_tolerance", "heading_tolerance",
                           "lookahead", "timeout") if not getattr(self, n) > 0]
        out = [f"{n}: must be > 0" for n in bad]
        if self.margin < 0:
            out.append("margin: must be >= 0 m")
        if self.goal_search < 0:
            out.append("goal_search: must be >= 0 m")
        return out


@dataclass(frozen=True)
class ArmSettings:
    """Arm planning: the robot ``model`` (sim model name, whose URDF is the planning
    model: ``locobot_wx250s`` or ``ur5e_robotiq``), ``tcp_offset`` [m] of the UR tool,
    OMPL ``algorithm``, ``time_limit`` [s] per attempt, ``attempts``, ``velocity_scale``
    and ``acceleration_scale`` (fractions of the joint limits), and the named poses
    (keys of the profile's ``named_poses``) used to ``stow`` the arm while driving,
    ``carry`` an item, ``look`` with an arm-mounted camera (None: camera not on the arm),
    and ``reach``: the posture that seeds IK for pick and place poses (its yaw joint
    turned towards the target; None: the current posture only). Planning runs on a
    worker thread; on a wall clock each tick waits at most ``plan_slice`` [wall s] for it
    (keep it well below the tick period), then yields; on a stepped clock (sim, mock) the
    tick waits for the plan, which costs exactly one tick of clock time."""

    model: Literal["locobot_wx250s", "ur5e_robotiq"] = "locobot_wx250s"
    tcp_offset: float = 0.155
    algorithm: Literal["rrtconnect", "rrtstar"] = "rrtconnect"
    time_limit: float = 1.0
    attempts: int = 3
    velocity_scale: float = 0.8
    acceleration_scale: float = 0.8
    stow: str = "sleep"
    carry: str = "sleep"
    look: str | None = None
    reach: str | None = None
    plan_slice: float = 0.015

    def validate(self) -> list[str]:
        out = []
        if not self.time_limit > 0 or self.attempts < 1:
            out.append("time_limit must be > 0 s and attempts >= 1")
        if not (0 < self.velocity_scale <= 1 and 0 < self.acceleration_scale <= 1):
            out.append("velocity_scale and acceleration_scale must be in (0, 1]")
        if not 0 <= self.plan_slice <= 0.1:
            out.append(f"plan_slice: expected 0..0.1 s of a tick, got {self.plan_slice}")
        return out


@dataclass(frozen=True)
class DepotSettings:
    """The depot: ``base`` pose [x, y, theta] in map where the base stops to place, and
    ``place`` [x, y, z] in map [m] where the held item's centre is released."""

    base: tuple[float, float, float]
    place: tuple[float, float, float]


@dataclass(frozen=True)
class FetchProfile:
    """The ``fetch:`` section of a robot profile (see docs/fetch.md).

    Lengths in m, angles in rad unless the name says ``deg``. ``item_size`` is the box
    [x, y, z] added to the planning scene; ``marker_length`` the black square's side;
    ``approach_distances`` stand-off distances from the marker face tried in order (the
    base-recovery indexes them); ``search_locations`` [x, y, theta] poses in map visited
    in order; ``grasp_depth`` how far behind the marker face the grasp point lies;
    ``grasp_height`` how far above the marker centre (along the marker's y, up) the pick
    and place poses lie: a gripper body thicker than the box is tall grasps the box's
    upper part so the body clears the board the box stands on;
    ``pre_grasp``, ``retract`` and ``place_retract`` offsets in the marker / place frame;
    ``refine_at`` the base's stand-off from the marker face [m] where ``approach`` looks
    again when the estimate was seen from afar (a wrist camera ahead of the base needs it
    farther than a head camera does); ``redetect_at_standoff``: ``approach`` looks at the
    marker once more from the stand-off pose it reached and keeps that estimate for the
    pick (a wrist camera in its look pose is then closest to the marker); ``grasp_force`` [N]; ``back_off`` [m] the base backs away after a pick; ``min_held_width`` [m]: a closed gripper narrower than this
    holds nothing."""

    depot: DepotSettings
    search_locations: list[tuple[float, float, float]] = field(default_factory=list)
    approach_distances: list[float] = field(default_factory=lambda: [0.35, 0.45, 0.55])
    item_size: tuple[float, float, float] = (0.06, 0.06, 0.06)
    marker_length: float = 0.045
    marker_dictionary: str = "DICT_4X4_50"
    search_step_deg: float = 30.0
    settle_time: float = 0.2
    detect_frames: int = 3
    grasp_depth: float = 0.03
    grasp_height: float = 0.0
    refine_at: float = 0.8
    redetect_at_standoff: bool = False
    pre_grasp: tuple[float, float, float] = (0.0, 0.0, 0.10)
    retract: tuple[float, float, float] = (0.0, 0.10, 0.10)
    place_retract: tuple[float, float, float] = (0.0, 0.0, 0.10)
    grasp_force: float = 20.0
    back_off: float = 0.25
    min_held_width: float = 0.01
    nav: NavSettings = field(default_factory=NavSettings)
    arm: ArmSettings = field(default_factory=ArmSettings)

    def validate(self) -> list[str]:
        out = []
        if not self.approach_distances or any(d <= 0 for d in self.approach_distances):
            out.append("approach_distances: expected a non-empty list of distances > 0 m")
        if min(self.item_size) <= 0 or self.marker_length <= 0:
            out.append("item_size and marker_length must be > 0 m")
        if not 1.0 <= self.search_step_deg <= 180.0:
            out.append(f"search_step_deg: expected 1..180, got {self.search_step_deg}")
        if self.refine_at <= 0:
            out.append(f"refine_at: expected > 0 m, got {self.refine_at:g}")
        if self.detect_frames < 1:
            out.append("detect_frames: expected >= 1")
        if not abs(self.grasp_height) < self.item_size[2] / 2:
            out.append(f"grasp_height: expected less than half the item's height ({self.item_size[2] / 2:g} m) "
                       f"from its centre, got {self.grasp_height:g} m")
        return out


_PROFILE_CACHE: dict[int, tuple[Any, FetchProfile]] = {}


def fetch_profile(ctx: SkillContext) -> FetchProfile:
    """The bound ``profile.fetch`` section; SkillFailure(PRECONDITION) naming the file
    position when it is missing or wrong."""
    raw = ctx.profile.get("fetch") if isinstance(ctx.profile, Mapping) else None
    if raw is None:
        raise SkillFailure(FailureKind.PRECONDITION,
                           "the robot profile has no 'fetch:' section (see docs/fetch.md for its keys)")
    cached = _PROFILE_CACHE.get(id(raw))
    if cached is not None and cached[0] is raw:
        return cached[1]
    problems = Problems()
    mark = mark_of(raw, Mark("<profile>", 1, 1))
    out = bind(FetchProfile, raw, mark, "profile.fetch", problems)
    if problems:
        raise SkillFailure(FailureKind.PRECONDITION, str(problems[0]))
    assert isinstance(out, FetchProfile)
    _PROFILE_CACHE[id(raw)] = (raw, out)
    return out


def check_profile(profile: Mapping[str, Any]) -> None:
    """Raise InputError with every problem of ``profile['fetch']`` (for config checks)."""
    problems = Problems()
    raw = profile.get("fetch")
    if raw is None:
        raise InputError.at(Mark("<profile>", 1, 1), "profile: missing 'fetch:' section")
    bind(FetchProfile, raw, mark_of(raw, Mark("<profile>", 1, 1)), "profile.fetch", problems)
    problems.raise_if_any()


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


# --------------------------------------------------------------------------- base helpers


def brake(ctx: SkillContext, base: Base, limit: float = 3.0) -> Generator[None, None, bool]:
    """Command zero velocity every tick until the base is at rest or ``limit`` clock
    seconds passed; returns whether it came to rest. Ignores further cancellation."""
    end = ctx.clock.now() + limit
    while True:
        base.stop()
        st = base.state()
        if abs(st.v) < STOPPED_V and abs(st.w) < STOPPED_W:
            return True
        if ctx.clock.now() > end:
            return False
        try:
            yield
        except SkillCancelled:
            continue
