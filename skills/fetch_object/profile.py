"""The robot profile's ``fetch_object:`` section: the catalogue, the detector, how to look,
where to stand and how to grasp an untagged object (docs/fetch_object.md).

Declared in :mod:`mmexec.skills.profile`, so a config's mistakes are reported when it
loads (``FILE:LINE:COL: profile.fetch_object.key: message``). The depot, the carry and
stow poses and the planner come from the ``fetch:`` and ``arm:`` sections the fetch
mission uses too.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from mmexec.skills.profile import declare_settings, setting

__all__ = ["DetectorSettings", "FetchObjectSettings", "GraspSettings", "fetch_object_settings", "resolve_path"]

#: the repository root: a relative path that does not exist from the working directory is
#: looked up here (the shipped catalogues and models)
ROOT = Path(__file__).resolve().parents[2]


def resolve_path(path: str) -> Path:
    """``path`` as given when absolute or found from the working directory, else from the
    repository root (where the shipped files are)."""
    p = Path(path)
    if p.is_absolute() or p.exists():
        return p
    return ROOT / p


@dataclass(frozen=True)
class DetectorSettings:
    """Which :class:`~mmexec.skills.perception.detector.ObjectDetector` finds the objects."""

    backend: Literal["colour", "onnx"] = setting(
        "colour", doc="colour: the classical colour/shape detector of the sim's object set; onnx: a YOLO model file")
    model: str = setting("", doc="onnx: the model file (.onnx, YOLOv5 or YOLOv8 export)")
    classes: list[str] = setting([], doc="onnx: class names in the model's order (default: the model's metadata)")
    layout: Literal["auto", "yolov5", "yolov8"] = setting("auto", doc="onnx: output layout")
    input_size: list[int] = setting([], doc="onnx: [W, H] model input for a model with a dynamic input")
    min_confidence: float = setting(0.4, ge=0, le=1, doc="detections below this confidence are ignored")


@dataclass(frozen=True)
class GraspSettings:
    """One grasp mode's offsets (grasp frame of :mod:`mmexec.skills.perception.grasp_point`:
    z out of the object towards the gripper, x the fingers' travel, y the tool's up)."""

    standoff: list[float] = setting([0.45, 0.5, 0.55], unit="m", gt=0,
                                    doc="base centre to object centre, tried in order (the recovery picks the start)")
    pre_grasp: tuple[float, float, float] = setting((0.0, 0.0, 0.10), unit="m", doc="pre-grasp offset, grasp frame")
    retract: tuple[float, float, float] = setting((0.0, 0.0, 0.12), unit="m", doc="retreat after the grasp, grasp frame")
    grasp_height: float = setting(0.0, unit="m", doc="every pick pose moved this far along the grasp frame's y")
    depth: float = setting(0.0, unit="m", doc=(
        "the grasp point moved this far into the object along the grasp frame's -z (negative: back out; for a top "
        "grasp, up: the finger tips then stay clear of the support under a flat object)"))


def _top() -> GraspSettings:
    return GraspSettings(depth=-0.01)


def _front() -> GraspSettings:
    return GraspSettings(standoff=[0.6, 0.64, 0.56], retract=(0.0, 0.10, 0.10))


@dataclass(frozen=True)
class FetchObjectSettings:
    """The ``fetch_object:`` section (docs/fetch_object.md)."""

    catalogue: str = setting("", doc="the item catalogue file (skills/catalogue.py; relative: from the working "
                                     "directory, else the repository)")
    detector: DetectorSettings = field(default_factory=DetectorSettings)
    grasp: Literal["top", "front"] = setting("top", doc="grasp of an item whose catalogue entry names none")
    top: GraspSettings = field(default_factory=_top)
    front: GraspSettings = field(default_factory=_front)
    views: list[float] = setting([0.0, 0.5, -0.5], unit="rad",
                                 doc="base headings (from the place's) looked from at each search stop")
    frames: int = setting(2, ge=1, le=10, doc="frames (predictions) per view, fused")
    settle_time: float = setting(0.3, unit="s", ge=0, doc="wait after a turn before looking")
    locate_pose: str | None = setting(None, refers_to="named_poses", doc=(
        "named arm pose taken before looking from the stand-off (a wrist camera pointed down at the object); "
        "None: the camera stays as it is (a head camera)"))
    operator_timeout: float = setting(60.0, unit="s", gt=0,
                                      doc="a dangerous item's prompt fails the request after this long unanswered")
    back_off: float = setting(0.2, unit="m", ge=0, doc="the base backs away this far after a pick")


fetch_object_settings = declare_settings("fetch_object", FetchObjectSettings, package="mmexec.skills.fetch_object",
                                         doc="the fetch_object mission: catalogue, detector, views, grasps")
