"""The classical detector of the simulator's object set, and the detector a profile picks.

:class:`PartsDetector` is an :class:`~mmexec.skills.perception.detector.ObjectDetector`
for objects told by the colours of their parts (:data:`SIM_OBJECT_CLASSES`: the kinds of
``sim/objects.py``, each a saturated colour, a two-part tool a second colour for its
head or blade). Per class:

1. the HSV mask of its main colour (OpenCV H 0-179), opened (speckle) and closed (the two
   handles of a pair of pliers, 15 mm apart, become one blob);
2. each blob of at least ``min_area`` pixels is a candidate; for a class with a second
   part, the pixels of that part's colour within ``join_px`` of the blob join it (the
   box then covers the whole tool);
3. confidence: the blob's fill of its minimum-area rectangle (solid boxes, bars and
   upright cylinders seen from the side fill it; clutter does not), times 1 when the
   second part was found and 0.6 when a two-part class shows only its main colour
   (a half-hidden tool still counts, with less trust).

Lighting changes value and a little saturation but not hue, so the ranges hold under
TinyRenderer's shading and the real lab's light alike; the floor, walls, wood and the
orange crate have hues or saturations outside them.

:func:`make_detector` builds the detector the profile's ``fetch_object.detector`` names:
``colour`` (this one) or ``onnx`` (a YOLO model file the user supplies,
:mod:`mmexec.skills.perception.yolo`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import cv2
import numpy as np

from mmexec.skills.perception.detector import Detection, HsvRange, ObjectDetector

__all__ = ["SIM_OBJECT_CLASSES", "PartClass", "PartsDetector", "make_detector"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class PartClass:
    """A class told by colour: ``main`` HSV ranges, and ``second`` ranges of a second part
    (empty: one part)."""

    name: str
    main: tuple[HsvRange, ...]
    second: tuple[HsvRange, ...] = ()


#: The object kinds of the simulator (sim/objects.py) by their parts' colours.
SIM_OBJECT_CLASSES: tuple[PartClass, ...] = (
    PartClass("box", (((0, 150, 40), (5, 255, 255)), ((174, 150, 40), (179, 255, 255)))),
    PartClass("cylinder", (((128, 120, 40), (145, 255, 255)),)),
    PartClass("screwdriver", (((22, 150, 60), (32, 255, 255)),), (((85, 150, 40), (98, 255, 255)),)),
    PartClass("pliers", (((155, 150, 40), (170, 255, 255)),), (((36, 150, 40), (48, 255, 255)),)),
    PartClass("pen", (((55, 150, 30), (75, 255, 255)),)),
)


def _mask(hsv: np.ndarray, ranges: tuple[HsvRange, ...]) -> np.ndarray:
    m = np.zeros(hsv.shape[:2], np.uint8)
    for lo, hi in ranges:
        m |= cv2.inRange(hsv, np.array(lo, np.uint8), np.array(hi, np.uint8))
    return m


@dataclass(frozen=True)
class PartsDetector:
    """The classical backend for the sim's object set (module doc). ``min_area`` [px] of a
    main-colour blob; ``join_px``: how far [px] a second part may lie from the main blob;
    ``close_px``: closing kernel [px]."""

    classes_: tuple[PartClass, ...] = SIM_OBJECT_CLASSES
    min_area: float = 40.0
    join_px: int = 6
    close_px: int = 5
    kernels: dict[str, np.ndarray] = field(default_factory=dict, compare=False, repr=False)

    @property
    def classes(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.classes_)

    def detect(self, rgb: np.ndarray) -> list[Detection]:
        """Objects of each class, most confident first (module doc)."""
        img = np.asarray(rgb)
        if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
            raise ValueError(f"detect: need an HxWx3 uint8 RGB image, got {img.dtype} {img.shape}")
        hsv = cv2.cvtColor(img, cv2.COLOR_RGB2HSV)
        k_open = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (3, 3))
        k_close = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (self.close_px, self.close_px))
        k_join = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * self.join_px + 1, 2 * self.join_px + 1))
        out: list[Detection] = []
        for cls in self.classes_:
            main = cv2.morphologyEx(cv2.morphologyEx(_mask(hsv, cls.main), cv2.MORPH_OPEN, k_open),
                                    cv2.MORPH_CLOSE, k_close)
            second = (cv2.morphologyEx(_mask(hsv, cls.second), cv2.MORPH_CLOSE, k_close)
                      if cls.second else None)
            # contours, not connected components: OpenCV's parallel labelling stalled on a busy
            # machine (80 ms a frame for 17 ms of CPU)
            mains, _ = cv2.findContours(main, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
            seconds = cv2.findContours(second, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)[0] if second is not None else ()
            H, W = main.shape
            for c in mains:
                area = float(cv2.contourArea(c))
                if area < self.min_area:
                    continue
                factor, parts = 1.0, [c]
                if second is not None:
                    bx, by, bw, bh = cv2.boundingRect(c)
                    x0, y0 = max(bx - self.join_px, 0), max(by - self.join_px, 0)
                    x1, y1 = min(bx + bw + self.join_px, W), min(by + bh + self.join_px, H)
                    blob = np.zeros((y1 - y0, x1 - x0), np.uint8)
                    cv2.drawContours(blob, [c - np.array([x0, y0])], -1, 1, cv2.FILLED)
                    near = cv2.dilate(blob, k_join) & second[y0:y1, x0:x1]
                    ys, xs = np.nonzero(near)
                    touch = [(float(x + x0), float(y + y0)) for x, y in zip(xs[::7], ys[::7])]
                    joined = [c2 for c2 in seconds
                              if any(cv2.pointPolygonTest(c2, pt, False) >= 0 for pt in touch)]
                    if joined:
                        parts += joined
                        area += sum(float(cv2.contourArea(c2)) for c2 in joined)
                    else:
                        factor = 0.6
                pts = np.vstack(parts)
                (_, _), (w, h), _ = cv2.minAreaRect(pts)
                conf = float(min(1.0, area / max(w * h, 1.0)) * factor)
                x, y, rw, rh = cv2.boundingRect(pts)
                out.append(Detection(cls.name, conf, (int(x), int(y), int(rw), int(rh))))
        out.sort(key=lambda d: -d.confidence)
        log.debug("parts detector: %d objects", len(out))
        return out


def make_detector(backend: str, *, model: str = "", classes: tuple[str, ...] = (), layout: str = "auto",
                  input_size: tuple[int, int] | None = None) -> ObjectDetector:
    """The detector of a profile's ``fetch_object.detector``: ``colour`` (:class:`PartsDetector`)
    or ``onnx`` (``model`` loaded by :func:`~mmexec.skills.perception.yolo.load_yolo`; raises
    :class:`~mmexec.skills.perception.yolo.ModelError` naming the file when it cannot be used)."""
    if backend == "colour":
        return PartsDetector()
    from mmexec.skills.perception.yolo import YoloConfig, load_yolo

    return load_yolo(YoloConfig(model=model, classes=tuple(classes), layout=layout,  # type: ignore[arg-type]
                                input_size=input_size))
