"""The ``scan`` skill: look at a place from four camera positions, detect objects twice in
each, and fuse what was seen into one list of objects in ``map``.

The paper (locobot-holistic-planning-dangerous-objects, section IV-C and IV-F) moves the
camera to four positions at each searching location and asks the detector twice at
each ("to mitigate the effect of the noise affecting the depth camera": 8 predictions
in about 10 s). Here:

1. **Camera positions** (``profile.scan``, :class:`ScanSettings`): on a robot with a
   pan/tilt :class:`~mmexec.drivers.interfaces.Head` (the LoCoBot) the ``head_poses``
   ``[pan, tilt]`` [rad], reached as head goals; without a head but with an arm (the UR
   platforms' wrist camera) the ``arm_poses``, named arm poses planned and executed like
   any named move; with neither, one view from where the camera is. After the last view
   the head returns to its home pose (:attr:`Head.home`); an arm stays at the last pose.
2. **Predictions**: at each position, after ``settle_time`` [s] of rest, ``predictions``
   frames, ``settle_time`` apart; each frame goes through the run's
   :class:`~mmexec.skills.perception.detector.ObjectDetector` (:func:`object_detector`:
   the one a skill left in ``ctx.world["perception.object_detector"]``, else the profile's
   ``scan.detector``: ``colour`` for the classical colour detector, or the path of a YOLO
   ``.onnx`` model, :mod:`mmexec.skills.perception.yolo`). Detections below
   ``min_confidence`` are dropped.
3. **Position in map** of each detection: its centre of mass from the box and the depth
   (:func:`~mmexec.skills.perception.grasp_point.estimate_grasp`, with the item's
   ``size`` when given), or, when too few depth points support that, the box centre's
   surface point (the paper's grasp point); no valid depth at all drops the detection.
   Every frame carries the camera pose of its capture, so the views agree in ``map``
   whatever the head did.
4. **Fusion** (:func:`fuse`): predictions of one class whose positions lie within
   ``merge_distance`` [m] of a group's mean join it (most confident first); a group's
   position and confidence are the means of its predictions.

Outputs (the skill's return, plain values for the blackboard):

* ``objects``: one dict per fused object, most confident first: ``label`` (the detector's
  class), ``confidence`` (mean over its predictions, in [0, 1]), ``position`` ``[x, y, z]``
  [m] in ``map`` (mean centre), ``seen`` (predictions that saw it, of ``predictions``
  ``x`` views), ``spread`` [m] (largest distance of a prediction from the mean);
* ``object``: the most confident object of the requested ``label`` (the same dict), or
  None when no label was asked for;
* ``views`` / ``predictions``: camera positions used and detector calls made.

The full result, with the frames, is in ``ctx.world["perception.scan"]``
(:class:`ScanResult`): each :class:`ScannedObject` keeps the frame and box of its best
prediction (``frame``, ``box``: the most confident) and of its last one (``last_frame``,
``last_box``: what the dangerous-object prompt shows the operator). A requested
``label`` that nothing matched fails EXECUTION ("no X seen ..."), so a mission moves on
to the next likely place. Events: ``scan_view`` per camera position (its pose and the
detections), ``scan_done`` (the fused objects).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Generator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mmexec.drivers.interfaces import CameraFrame
from mmexec.skills.base import (
    FailureKind,
    Output,
    Param,
    SkillContext,
    SkillFailure,
    SkillGen,
    skill,
    wait_goal,
)
from mmexec.skills.manipulation.arm import move_named
from mmexec.skills.perception.detector import ColourBlobDetector, Detection, ObjectDetector
from mmexec.skills.perception.grasp_point import (
    GraspPointConfig,
    GraspPointError,
    back_project,
    estimate_grasp,
    pixel_depth,
)
from mmexec.skills.profile import declare_settings, setting

__all__ = [
    "WORLD_OBJECT_DETECTOR",
    "WORLD_SCAN",
    "Prediction",
    "ScanResult",
    "ScanSettings",
    "ScannedObject",
    "fuse",
    "locate",
    "object_detector",
    "point_head",
    "scan",
    "scan_place",
    "scan_settings",
]

log = logging.getLogger(__name__)

#: world-model key of the run's object detector (an :class:`ObjectDetector`)
WORLD_OBJECT_DETECTOR = "perception.object_detector"
#: world-model key of the latest :class:`ScanResult`
WORLD_SCAN = "perception.scan"

Box = tuple[int, int, int, int]


@dataclass(frozen=True)
class ScanSettings:
    """The ``scan:`` section of a robot profile: camera positions, predictions, fusion."""

    head_poses: list[tuple[float, float]] = setting(
        [(0.6, 0.35), (0.2, 0.35), (-0.2, 0.35), (-0.6, 0.35)], unit="rad, rad",
        doc="pan/tilt head poses [pan, tilt] of a scan, in order (robots with a head)")
    arm_poses: list[str] = setting(
        [], doc="named arm poses (named_poses) of a scan with a wrist camera, in order (robots without a head)")
    predictions: int = setting(2, ge=1, le=20, doc="detector calls at each camera position (the paper: two)")
    settle_time: float = setting(0.3, unit="s", ge=0, doc="rest before each prediction")
    merge_distance: float = setting(0.1, unit="m", gt=0, doc="predictions of one class closer than this are one object")
    min_confidence: float = setting(0.3, ge=0, le=1, doc="detections below this confidence are dropped")
    detector: str = setting("colour", doc="'colour' (classical colour detector) or the path of a YOLO .onnx model")

    def validate(self) -> list[str]:
        return [f"head_poses[{i}]: expected [pan, tilt] [rad], got {list(p)}"
                for i, p in enumerate(self.head_poses) if len(p) != 2]


scan_settings = declare_settings("scan", ScanSettings, package=__name__,
                                 doc="the scan skill: camera positions, predictions per position, fusion")


@dataclass(frozen=True, eq=False)
class Prediction:
    """One detection placed in ``map``: class ``label``, ``confidence``, ``position`` (3,)
    [m] in ``map``, the ``frame`` and ``box`` ``(x, y, w, h)`` [px] it came from, and the
    camera position's index ``view``."""

    label: str
    confidence: float
    position: np.ndarray
    frame: CameraFrame
    box: Box
    view: int


@dataclass(eq=False)
class ScannedObject:
    """One object after fusion (see the module doc): ``label``, mean ``confidence``, mean
    ``position`` (3,) [m] in ``map``, its ``predictions``; ``frame``/``box`` of the most
    confident one, ``last_frame``/``last_box`` of the latest one."""

    label: str
    predictions: list[Prediction] = field(default_factory=list)

    @property
    def position(self) -> np.ndarray:
        return np.mean([p.position for p in self.predictions], axis=0)

    @property
    def confidence(self) -> float:
        return float(np.mean([p.confidence for p in self.predictions]))

    @property
    def seen(self) -> int:
        return len(self.predictions)

    @property
    def spread(self) -> float:
        """Largest distance [m] of a prediction from the mean position."""
        c = self.position
        return float(max(np.linalg.norm(p.position - c) for p in self.predictions))

    @property
    def best(self) -> Prediction:
        return max(self.predictions, key=lambda p: p.confidence)

    @property
    def frame(self) -> CameraFrame:
        return self.best.frame

    @property
    def box(self) -> Box:
        return self.best.box

    @property
    def last_frame(self) -> CameraFrame:
        return self.predictions[-1].frame

    @property
    def last_box(self) -> Box:
        return self.predictions[-1].box

    def as_dict(self) -> dict[str, Any]:
        """The plain record of the ``objects`` output."""
        return {"label": self.label, "confidence": round(self.confidence, 4),
                "position": [round(float(v), 4) for v in self.position], "seen": self.seen,
                "spread": round(self.spread, 4)}


@dataclass
class ScanResult:
    """A scan: the fused ``objects`` (most confident first), camera positions ``views``,
    detector calls ``predictions``, every placed :class:`Prediction` in ``raw``."""

    objects: list[ScannedObject]
    views: int
    predictions: int
    raw: list[Prediction]

    def best(self, label: str) -> ScannedObject | None:
        """The most confident object of class ``label`` (None when none was seen)."""
        return next((o for o in self.objects if o.label == label), None)


def fuse(predictions: Sequence[Prediction], merge_distance: float) -> list[ScannedObject]:
    """Group ``predictions`` into objects: each, most confident first, joins the nearest
    group of its class whose mean position is within ``merge_distance`` [m], or starts
    one. Within a group the predictions keep their capture order (so the last one is the
    latest frame). Returns the groups, most confident first."""
    groups: list[ScannedObject] = []
    order = {id(p): k for k, p in enumerate(predictions)}
    for pred in sorted(predictions, key=lambda p: -p.confidence):
        near = [(float(np.linalg.norm(g.position - pred.position)), g) for g in groups if g.label == pred.label]
        near = [(d, g) for d, g in near if d <= merge_distance]
        if near:
            group = min(near, key=lambda x: x[0])[1]
            group.predictions.append(pred)
            group.predictions.sort(key=lambda p: order[id(p)])
        else:
            groups.append(ScannedObject(pred.label, [pred]))
    groups.sort(key=lambda g: (-g.confidence, -g.seen))
    return groups


def locate(frame: CameraFrame, box: Box, *, size: tuple[float, float, float] | None = None,
           config: GraspPointConfig | None = None) -> np.ndarray | None:
    """The object's position (3,) [m] in ``map`` from its ``box`` in ``frame``: the centre
    of mass from the depth points (:func:`estimate_grasp`), else the box centre's surface
    point; None when the box has no valid depth."""
    try:
        return estimate_grasp(frame, box, size=size, config=config).centre
    except GraspPointError as e:
        log.debug("scan: no centre of mass for box %s (%s): the surface point instead", box, e)
    if frame.depth is None:
        return None
    cfg = config or GraspPointConfig()
    x, y, w, h = box
    H, W = frame.depth.shape[:2]
    x0, y0, x1, y1 = max(x, 0), max(y, 0), min(x + w - 1, W - 1), min(y + h - 1, H - 1)
    if x1 < x0 or y1 < y0:
        return None
    px = ((x0 + x1) / 2.0, (y0 + y1) / 2.0)
    try:
        z = pixel_depth(np.asarray(frame.depth, float), px, (max(1, w // 10), max(1, h // 10)),
                        limit=(x0, y0, x1, y1), depth_range=cfg.depth_range, min_valid=cfg.min_valid)
    except GraspPointError:
        return None
    T = np.asarray(frame.T_map_base, float) @ np.asarray(frame.T_base_camera, float)
    return T[:3, :3] @ back_project(px, z, frame.intrinsics) + T[:3, 3]


def object_detector(ctx: SkillContext) -> ObjectDetector:
    """The run's object detector: ``ctx.world["perception.object_detector"]`` when set,
    else built once from ``profile.scan.detector`` and kept there."""
    det = ctx.world.get(WORLD_OBJECT_DETECTOR)
    if det is not None:
        return det  # type: ignore[no-any-return]
    name = scan_settings(ctx).detector
    if name == "colour":
        det = ColourBlobDetector()
    elif name.endswith(".onnx"):
        from mmexec.skills.perception.yolo import ModelError, YoloConfig, load_yolo

        try:
            det = load_yolo(YoloConfig(model=name))
        except (ModelError, OSError, ValueError) as e:
            raise SkillFailure(FailureKind.PRECONDITION, f"scan: profile scan.detector: {e}") from None
    else:
        raise SkillFailure(FailureKind.PRECONDITION,
                           f"scan: profile scan.detector must be 'colour' or a .onnx model path, got {name!r}")
    ctx.world[WORLD_OBJECT_DETECTOR] = det
    return det


def _wait(ctx: SkillContext, seconds: float) -> Generator[None, None, None]:
    end = ctx.clock.now() + seconds
    while ctx.clock.now() < end - 1e-9:
        yield


def _positions(ctx: SkillContext, cfg: ScanSettings) -> list[tuple[str, Any]]:
    """The camera positions: ("head", (pan, tilt)), ("arm", name) or one ("here", None)."""
    if ctx.robot.head is not None and cfg.head_poses:
        return [("head", (float(p[0]), float(p[1]))) for p in cfg.head_poses]
    if ctx.robot.arm is not None and cfg.arm_poses:
        return [("arm", name) for name in cfg.arm_poses]
    return [("here", None)]


def scan_place(ctx: SkillContext, *, detector: ObjectDetector | None = None, labels: Sequence[str] | None = None,
               size: tuple[float, float, float] | None = None, predictions: int | None = None,
               cfg: ScanSettings | None = None) -> Generator[None, None, ScanResult]:
    """Scan from the profile's camera positions (see the module doc) and return the fused
    :class:`ScanResult` (also left in ``ctx.world["perception.scan"]``). ``labels``: keep
    only these classes (None: all); ``size``: the item's size [m] for the centre of mass.
    Building block of :func:`scan` for other skills (``yield from scan_place(ctx)``)."""
    cfg = cfg or scan_settings(ctx)
    det = detector or object_detector(ctx)
    n_pred = cfg.predictions if predictions is None else predictions
    camera, head = ctx.robot.camera, ctx.robot.head
    if camera is None:
        raise SkillFailure(FailureKind.PRECONDITION, "scan needs a camera, and this robot has none")
    raw: list[Prediction] = []
    calls = 0
    positions = _positions(ctx, cfg)
    moved_head = False
    try:
        for view, (kind, where) in enumerate(positions):
            if kind == "head":
                assert head is not None
                moved_head = True
                yield from wait_goal(ctx, head.point(*where), timeout=10.0)
            elif kind == "arm":
                yield from move_named(ctx, where)
            seen: list[dict[str, Any]] = []
            for _ in range(n_pred):
                yield from _wait(ctx, cfg.settle_time)
                frame = camera.frame()
                if frame is None:
                    yield
                    frame = camera.frame()
                if frame is None:
                    log.warning("scan: no camera frame at view %d", view)
                    continue
                calls += 1
                for d in det.detect(frame.rgb):
                    if d.confidence < cfg.min_confidence or (labels is not None and d.label not in labels):
                        continue
                    pos = locate(frame, d.box, size=size)
                    if pos is None:
                        continue
                    raw.append(Prediction(d.label, float(d.confidence), np.asarray(pos, float), frame,
                                          tuple(int(v) for v in d.box), view))  # type: ignore[arg-type]
                    seen.append(_event_detection(d, pos))
                yield
            ctx.emit("scan_view", view=view, camera=kind, at=_event_pose(where), detections=seen, node=ctx.node_path)
    except BaseException:
        if moved_head and head is not None:
            # back to the robot's default head pose when the scan failed or was cancelled
            # too (a cancelled wait_goal has already stopped the head; not waited for)
            head.point(*head.home)
        raise
    if moved_head and head is not None:
        home = head.point(*head.home)
        yield from wait_goal(ctx, home, timeout=10.0)
    objects = fuse(raw, cfg.merge_distance)
    result = ScanResult(objects, len(positions), calls, raw)
    ctx.world[WORLD_SCAN] = result
    ctx.emit("scan_done", views=len(positions), predictions=calls, objects=[o.as_dict() for o in objects],
             node=ctx.node_path)
    return result


def _event_detection(d: Detection, pos: np.ndarray) -> dict[str, Any]:
    return {"label": d.label, "confidence": round(float(d.confidence), 4), "box": [int(v) for v in d.box],
            "position": [round(float(v), 4) for v in pos]}


def _event_pose(where: Any) -> Any:
    if isinstance(where, tuple):
        return [round(float(v), 4) for v in where]
    return where


@skill(
    "scan",
    params=[
        Param("label", str, doc="the class looked for: fail when none is seen (default: report every class)"),
        Param("size", list, unit="m", doc="the item's size [sx, sy, height] for the centre of mass (default: as seen)"),
        Param("predictions", int, doc="detector calls per camera position (default: profile scan.predictions)"),
    ],
    outputs=[
        Output("objects", list, doc="fused objects, most confident first: {label, confidence, position [x, y, z] "
                                    "in map [m], seen, spread [m]}"),
        Output("object", dict, doc="the most confident object of the requested label (None without a label)"),
        Output("views", int, doc="camera positions used"),
        Output("predictions", int, doc="detector calls made"),
    ],
    needs=("camera",),
)
def scan(ctx: SkillContext, label: str | None = None, size: list[float] | None = None,
         predictions: int | None = None) -> SkillGen:
    """Scan the place in front of the robot from the profile's camera positions (head
    pan/tilt poses, or wrist poses through the arm), ``predictions`` detector calls at
    each, and fuse the detections in map. With ``label``: EXECUTION "no LABEL seen" when
    none was. The frames and boxes stay in the world model (``perception.scan``)."""
    if predictions is not None and not 1 <= predictions <= 20:
        raise SkillFailure(FailureKind.PRECONDITION, f"scan: predictions must be 1..20, got {predictions}")
    sz: tuple[float, float, float] | None = None
    if size is not None:
        if len(size) != 3 or not all(isinstance(v, (int, float)) and math.isfinite(v) and v > 0 for v in size):
            raise SkillFailure(FailureKind.PRECONDITION, f"scan: size must be three lengths > 0 [m], got {size}")
        sz = (float(size[0]), float(size[1]), float(size[2]))
    result = yield from scan_place(ctx, labels=None if label is None else [label], size=sz, predictions=predictions)
    best = result.best(label) if label is not None else None
    if label is not None and best is None:
        raise SkillFailure(FailureKind.EXECUTION,
                           f"scan: no {label!r} seen in {result.predictions} predictions from {result.views} views")
    return {"objects": [o.as_dict() for o in result.objects], "object": best.as_dict() if best is not None else None,
            "views": result.views, "predictions": result.predictions}


@skill(
    "point_head",
    params=[
        Param("pan", float, unit="rad", doc="pan, positive turns the camera left (default: the head's home)"),
        Param("tilt", float, unit="rad", doc="tilt, positive looks down (default: the head's home)"),
        Param("timeout", float, unit="s", default=10.0, doc="give up after this much clock time"),
    ],
    outputs=[Output("pan", float, doc="measured pan [rad]"), Output("tilt", float, doc="measured tilt [rad]")],
)
def point_head(ctx: SkillContext, pan: float | None = None, tilt: float | None = None,
               timeout: float = 10.0) -> SkillGen:
    """Point the pan/tilt head: move to ``pan`` and ``tilt`` [rad] (each defaults to the
    head's home value), e.g. the sim's 20 degree tilt (0.35) before a marker search on the
    real LoCoBot. PRECONDITION on a robot without a head; EXECUTION when the head refuses
    (a target outside its limits) or fails."""
    head = ctx.robot.head
    if head is None:
        raise SkillFailure(FailureKind.PRECONDITION, "point_head needs a pan/tilt head, and this robot has none")
    home_pan, home_tilt = head.home
    yield from wait_goal(ctx, head.point(home_pan if pan is None else pan, home_tilt if tilt is None else tilt),
                         timeout=timeout)
    st = head.state()
    return {"pan": st.pan, "tilt": st.tilt}
