"""Marker detection skills: capture a few frames, detect the requested ArUco marker,
estimate its pose (IPPE + depth refinement, in ``map`` through the camera mount and the
base pose) and average the frames (:mod:`mmexec.skills.perception`).

Skill: ``detect_marker``; :func:`look` is the building block other skills use (search,
approach). Settings: the profile's ``camera:`` section (:class:`CameraSettings`: the
markers' dictionary and size, frames averaged). Every estimate goes to the world model
(``ctx.world``) under ``perception.markers`` (:func:`markers`), the detector under
``perception.detector``.

Frames are expensive (a rendered frame in sim costs tens of milliseconds), so skills
capture only when they need a view, and :func:`look` stops after the first frame when the
marker is not in it.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Generator
from dataclasses import dataclass
from typing import Any

import numpy as np

from mmexec.drivers.interfaces import Camera, CameraFrame
from mmexec.skills.base import (
    FailureKind,
    Output,
    Param,
    SkillContext,
    SkillFailure,
    SkillGen,
    skill,
)
from mmexec.skills.perception import (
    DetectorConfig,
    MarkerDetector,
    MarkerPoseEstimator,
    observe_markers,
)
from mmexec.skills.perception.markers import MarkerObservation, depth_plane_normal
from mmexec.skills.profile import declare_settings, setting

__all__ = [
    "WORLD_DETECTOR",
    "WORLD_MARKERS",
    "CameraSettings",
    "MarkerEstimate",
    "camera_settings",
    "detect_marker",
    "detector",
    "emit_estimate",
    "look",
    "markers",
]

log = logging.getLogger(__name__)

WORLD_MARKERS = "perception.markers"
WORLD_DETECTOR = "perception.detector"

#: Longest a skill waits for a camera frame before giving up [clock s].
FRAME_TIMEOUT = 2.0


@dataclass(frozen=True)
class CameraSettings:
    """The ``camera:`` section of a robot profile: the markers the camera looks for and
    how many frames an estimate averages (the camera itself is ``robot.camera``)."""

    marker_length: float = setting(0.045, unit="m", gt=0, doc="side of the marker's black square")
    marker_dictionary: str = setting("DICT_4X4_50", doc="ArUco dictionary")
    detect_frames: int = setting(3, ge=1, doc="frames averaged per detection")


camera_settings = declare_settings("camera", CameraSettings, package=__name__,
                                   doc="marker detection: the markers' dictionary and size, frames averaged")


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


def markers(ctx: SkillContext) -> dict[int, MarkerEstimate]:
    """The world model's marker estimates by id (created on first use)."""
    return ctx.world.setdefault(WORLD_MARKERS, {})


def detector(ctx: SkillContext) -> MarkerDetector:
    """The run's marker detector (kept in ``ctx.world``; built from the camera section)."""
    cam = camera_settings(ctx)
    det = ctx.world.get(WORLD_DETECTOR)
    if det is None or det.config.marker_length != cam.marker_length or det.config.dictionary != cam.marker_dictionary:
        det = MarkerDetector(DetectorConfig(dictionary=cam.marker_dictionary, marker_length=cam.marker_length))
        ctx.world[WORLD_DETECTOR] = det
    return det


def depth_oriented(ob: MarkerObservation, frame: CameraFrame) -> np.ndarray:
    """``T_map_marker`` of ``ob`` with its z axis (the face normal) taken from a plane fitted
    to the depth inside the marker, when the frame has depth: the rotation from the four
    corners of a 45 mm marker is off by 10 degrees or more beyond ~0.8 m, the depth
    plane's is not. The marker's x axis is kept, projected onto the plane. Without usable
    depth the observation's own pose is returned."""
    if frame.depth is None:
        return ob.T_map_marker
    nrm = depth_plane_normal(ob.corners, frame.depth, frame.intrinsics)
    if nrm is None:
        return ob.T_map_marker
    T_cm = np.array(ob.T_camera_marker, dtype=float)
    z = np.asarray(nrm, dtype=float)
    x = T_cm[:3, 0] - np.dot(T_cm[:3, 0], z) * z
    if np.linalg.norm(x) < 1e-6:
        return ob.T_map_marker
    x /= np.linalg.norm(x)
    T_cm[:3, 0], T_cm[:3, 1], T_cm[:3, 2] = x, np.cross(z, x), z
    return np.asarray(frame.T_map_base) @ np.asarray(frame.T_base_camera) @ T_cm


def next_frame(ctx: SkillContext, camera: Camera, timeout: float = FRAME_TIMEOUT) -> Generator[None, None, CameraFrame]:
    """The camera's newest frame: at once when it has one, else yielding a tick at a time;
    SkillFailure EXECUTION when none comes within ``timeout`` clock seconds [s]. Every
    skill that waits for a frame waits through this (a camera that stops must not hang
    a skill)."""
    deadline = ctx.clock.now() + timeout
    while True:
        frame = camera.frame()
        if frame is not None:
            return frame
        if ctx.clock.now() > deadline:
            raise SkillFailure(FailureKind.EXECUTION, f"camera gave no frame for {timeout:g} s")
        yield


def look(ctx: SkillContext, marker: int, frames: int, *, record_all: bool = True) -> Generator[None, None, MarkerEstimate | None]:
    """Capture up to ``frames`` frames (one per tick) and average the poses of ``marker``.

    Returns None when the marker is not in the first frame (no more frames are spent).
    Every other marker seen is recorded in the world model too (``record_all``). A
    camera that gives no frame for ``FRAME_TIMEOUT`` clock seconds fails with EXECUTION.
    """
    cam = ctx.robot.camera
    if cam is None:
        raise SkillFailure(FailureKind.PRECONDITION, "marker detection needs a camera, and this robot has none")
    # wanting the marker: when the downscaled pass finds only others (a small marker at the
    # image's edge), the full-resolution pass still looks for it; every marker is returned
    det = detector(ctx)
    est = MarkerPoseEstimator(min_samples=1, window=max(1, frames))
    others: dict[int, Any] = {}
    closest = np.inf
    got = 0
    while got < frames:
        frame = yield from next_frame(ctx, cam)
        got += 1
        seen = False
        for ob in observe_markers(frame, det, want={marker}):
            if ob.id == marker:
                est.add(depth_oriented(ob, frame))
                closest = min(closest, ob.distance)
                seen = True
            elif record_all:
                others[ob.id] = ob
        if not seen and est.count == 0:
            break
        if got < frames:
            yield
    stamp = ctx.clock.now()
    world = markers(ctx)
    for mid, ob in others.items():
        world[mid] = MarkerEstimate(mid, ob.T_map_marker, 1, stamp, ob.distance)
    if est.count == 0:
        return None
    avg = est.estimate()
    result = MarkerEstimate(marker, avg.T, avg.used, stamp, float(closest))
    world[marker] = result
    log.debug("marker %d at %s from %d frames", marker, np.round(avg.T[:3, 3], 3), avg.used)
    return result


def emit_estimate(ctx: SkillContext, est: MarkerEstimate) -> None:
    """Write a ``marker_estimate`` event: marker, pose [x, y, z, yaw] in map [m, rad],
    samples, distance [m] it was seen from."""
    ctx.emit("marker_estimate", marker=est.marker, pose=[round(v, 4) for v in est.as_list()], samples=est.samples,
             distance=round(est.distance, 3), node=ctx.node_path)


@skill(
    "detect_marker",
    params=[
        Param("marker", int, required=True, doc="ArUco id of the item's marker"),
        Param("frames", int, doc="frames to average (default: profile camera.detect_frames)"),
        Param("max_distance", float, unit="m", doc="fail when the marker is seen only farther than this"),
    ],
    outputs=[
        Output("pose", list, doc="[x, y, z, yaw] of the marker in map [m, rad], yaw of its outward normal"),
        Output("distance", float, doc="camera to marker [m]"),
    ],
    needs=("camera",),
)
def detect_marker(ctx: SkillContext, marker: int, frames: int | None = None,
                  max_distance: float | None = None) -> SkillGen:
    """Detect marker ``marker`` in the current view, average its map pose over a few
    frames, store it in the world model (``perception.markers``) and output it. Fails with
    PRECONDITION "marker K not in view" when the camera does not see it."""
    n = frames if frames is not None else camera_settings(ctx).detect_frames
    if n < 1:
        raise SkillFailure(FailureKind.PRECONDITION, f"detect_marker: frames must be >= 1, got {n}")
    est = yield from look(ctx, marker, n)
    if est is None:
        raise SkillFailure(FailureKind.PRECONDITION, f"marker {marker} not in view")
    if max_distance is not None and est.distance > max_distance:
        raise SkillFailure(FailureKind.PRECONDITION,
                           f"marker {marker} seen at {est.distance:.2f} m, farther than {max_distance:g} m")
    emit_estimate(ctx, est)
    return {"pose": est.as_list(), "distance": est.distance}
