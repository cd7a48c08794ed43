"""Named poses of the robot profile, looked up by the skills that take a pose by name.

* Base poses [x, y, theta] in ``map`` [m, m, rad]: ``home`` (profile ``home``), the keys
  of profile ``places``, and names a skill package adds with :func:`add_base_pose` (the
  fetch package's ``depot``: ``fetch.depot.base``). ``navigate goal:``, ``drive_to
  place:`` and search locations given by name use :func:`base_pose`.
* Arm joint poses [rad], in the arm's joint order: the keys of profile ``named_poses``
  (``move_arm pose:``, the arm section's roles ``stow``, ``carry``, ``look``, ``reach``),
  through :func:`arm_joints`.

A name the profile does not hold is a PRECONDITION failure listing the known names.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from mmexec.drivers.interfaces import Pose2D
from mmexec.skills.base import FailureKind, SkillContext, SkillFailure

__all__ = ["add_base_pose", "arm_joints", "base_pose", "pose_list"]


@dataclass(frozen=True)
class _ExtraPose:
    """A base pose name a skill package adds: it exists when the profile holds
    ``section``, and ``lookup`` reads it (raising SkillFailure when it is wrong)."""

    section: str
    lookup: Callable[[SkillContext], Pose2D]


_EXTRA: dict[str, _ExtraPose] = {}


def add_base_pose(name: str, section: str, lookup: Callable[[SkillContext], Pose2D]) -> None:
    """Make ``name`` a base pose for :func:`base_pose` whenever the profile holds section
    ``section``; ``lookup(ctx)`` returns it in ``map``. Adding a name again replaces it."""
    _EXTRA[name] = _ExtraPose(section, lookup)


def _numbers(value: Any) -> bool:
    return isinstance(value, Sequence) and not isinstance(value, str) and all(
        isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)


def pose_list(value: Any, what: str) -> Pose2D:
    """``[x, y, theta]`` (map [m, m, rad]) -> Pose2D, or SkillFailure(PRECONDITION) naming ``what``."""
    if not _numbers(value) or len(value) != 3:
        raise SkillFailure(FailureKind.PRECONDITION, f"{what}: expected [x, y, theta] in map, got {value!r}")
    return Pose2D(float(value[0]), float(value[1]), float(value[2]))


def base_pose(ctx: SkillContext, name: str, who: str = "") -> Pose2D:
    """The base pose named ``name`` in ``map``: ``home``, a name a skill package added
    (:func:`add_base_pose`) or a key of the profile's ``places``. ``who`` (a skill name)
    prefixes the failure message."""
    prof = ctx.profile
    if name == "home" and "home" in prof:
        return pose_list(prof["home"], "profile.home")
    extra = _EXTRA.get(name)
    if extra is not None and extra.section in prof:
        return extra.lookup(ctx)
    places = prof.get("places") or {}
    if isinstance(places, Mapping) and name in places:
        return pose_list(places[name], f"profile.places.{name}")
    known = [k for k in ("home",) if k in prof] + [n for n, e in _EXTRA.items() if e.section in prof]
    known += sorted(places) if isinstance(places, Mapping) else []
    raise SkillFailure(FailureKind.PRECONDITION, f"{who + ': ' if who else ''}no base pose named {name!r} "
                                                 f"in the robot profile (known: {', '.join(known) or 'none'})")


def arm_joints(profile: Mapping[str, Any], name: str, who: str = "") -> list[float]:
    """The arm joint pose ``name`` of the profile's ``named_poses`` [rad], in the arm's
    joint order. ``who`` (a skill name) prefixes the failure message."""
    prefix = f"{who}: " if who else ""
    poses = profile.get("named_poses") or {}
    if not isinstance(poses, Mapping) or name not in poses:
        known = sorted(poses) if isinstance(poses, Mapping) else []
        raise SkillFailure(FailureKind.PRECONDITION,
                           f"{prefix}no named pose {name!r} in the robot profile (known: {', '.join(known) or 'none'})")
    q = poses[name]
    if not _numbers(q):
        raise SkillFailure(FailureKind.PRECONDITION, f"{prefix}profile pose {name!r} is not a list of numbers")
    return [float(x) for x in q]
