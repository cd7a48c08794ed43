"""Object detector interface (class, confidence, box) and a classical colour/shape backend
for coloured spheres: red apples and coloured balls.

The thesis (ros2-thesis-follower-buttons-fruit, section 1.3.4) detects balls and apples
with a neural network (bounding box, class, confidence), slow on its robot's CPU (about
0.5 s per image) and prone to false positives after training on a small data set; the
box then seeds the sphere fit (Algorithm 1.2) with a colour mask chosen by the class.
Here :class:`ObjectDetector` is the interface a skill uses: ``detect(rgb)`` returns
:class:`Detection` records (class label, confidence in [0, 1], axis-aligned box in
pixels). A learned backend (ONNX) goes behind the same interface later; this module's
:class:`ColourBlobDetector` is the classical one for the simulator's and the lab's
saturated objects:

1. per class, an HSV threshold (OpenCV's H in 0-179, so red takes two ranges), then a
   morphological opening (speckle) and closing (the specular highlight, whose low
   saturation leaves a hole, and the shading's dark rim);
2. external contours of the mask; each blob's shape is scored by its circularity
   ``4 pi A / P^2`` (1 for a disc) times its fill of the minimum enclosing circle
   ``A / (pi r^2)`` (1 for a disc; 0.64 for a square, lower for elongated shapes);
3. that product is the confidence; blobs below ``min_area`` or ``min_confidence`` are
   dropped. A partly hidden ball scores lower (half a disc: about 0.4), which the
   priority score (:mod:`.priority`) then holds against it as it does a low network
   confidence.

Two touching balls of one colour make one blob of low circularity and are missed; a
learned backend is the answer there. :func:`colour_mask` gives the pixels of a class'
colour inside a box, Algorithm 1.2's colour mask, for any backend's detections.

Images are HxWx3 uint8 in RGB order (:class:`mmexec.drivers.interfaces.CameraFrame`);
boxes are ``(x, y, w, h)`` in pixels of that image.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Protocol

import cv2
import numpy as np

__all__ = [
    "DEFAULT_CLASSES",
    "ColourBlobDetector",
    "ColourClass",
    "ColourDetectorConfig",
    "Detection",
    "ObjectDetector",
    "blob_confidence",
    "colour_mask",
]

log = logging.getLogger(__name__)

Box = tuple[int, int, int, int]
HsvRange = tuple[tuple[int, int, int], tuple[int, int, int]]


@dataclass(frozen=True)
class Detection:
    """One detected object: ``label`` (the class name), ``confidence`` in [0, 1], ``box``
    ``(x, y, w, h)`` [px], top-left corner and size."""

    label: str
    confidence: float
    box: Box


class ObjectDetector(Protocol):
    """What a skill needs of a detector. ``classes``: the labels it can return;
    ``detect``: the objects in one HxWx3 uint8 RGB image, most confident first."""

    @property
    def classes(self) -> tuple[str, ...]: ...

    def detect(self, rgb: np.ndarray) -> list[Detection]: ...


@dataclass(frozen=True)
class ColourClass:
    """A class told by colour: ``hsv`` ranges (inclusive lower, upper) in OpenCV HSV (H
    0-179, S and V 0-255); a pixel in any range has the colour."""

    name: str
    hsv: tuple[HsvRange, ...]


#: The thesis' objects: red apples and coloured balls. Saturation and value floors keep
#: grey clutter, the specular highlight and the darkest rim out.
DEFAULT_CLASSES: tuple[ColourClass, ...] = (
    ColourClass("apple", (((0, 120, 50), (8, 255, 255)), ((172, 120, 50), (179, 255, 255)))),
    ColourClass("yellow_ball", (((22, 120, 40), (35, 255, 255)),)),
    ColourClass("green_ball", (((45, 120, 40), (80, 255, 255)),)),
    ColourClass("blue_ball", (((100, 120, 40), (128, 255, 255)),)),
)


def _hsv_mask(hsv: np.ndarray, cls: ColourClass) -> np.ndarray:
    m = np.zeros(hsv.shape[:2], np.uint8)
    for lo, hi in cls.hsv:
        m |= cv2.inRange(hsv, np.array(lo, np.uint8), np.array(hi, np.uint8))
    return m


def colour_mask(rgb: np.ndarray, cls: ColourClass, box: Box | None = None) -> np.ndarray:
    """HxW bool: the pixels of ``cls``' colour (inside ``box`` when given; False outside
    it), Algorithm 1.2's colour mask for the fit's point cloud."""
    h, w = rgb.shape[:2]
    x0, y0, x1, y1 = 0, 0, w, h
    if box is not None:
        x0, y0 = max(int(box[0]), 0), max(int(box[1]), 0)
        x1, y1 = min(int(box[0] + box[2]), w), min(int(box[1] + box[3]), h)
    out = np.zeros((h, w), dtype=bool)
    if x1 > x0 and y1 > y0:
        hsv = cv2.cvtColor(np.ascontiguousarray(rgb[y0:y1, x0:x1]), cv2.COLOR_RGB2HSV)
        out[y0:y1, x0:x1] = _hsv_mask(hsv, cls) > 0
    return out


@dataclass(frozen=True)
class ColourDetectorConfig:
    """``classes``; ``min_area`` [px] of a blob; ``min_confidence`` (circularity x fill,
    see the module docstring); ``open_px`` / ``close_px``: sizes [px] of the elliptic
    opening and closing kernels (0: none)."""

    classes: tuple[ColourClass, ...] = DEFAULT_CLASSES
    min_area: float = 60.0
    min_confidence: float = 0.55
    open_px: int = 3
    close_px: int = 7

    def validate(self) -> list[str]:
        errs = []
        names = [c.name for c in self.classes]
        if not names:
            errs.append("classes: need at least one")
        if len(set(names)) != len(names):
            errs.append(f"classes: names must be unique, got {names}")
        for c in self.classes:
            for lo, hi in c.hsv:
                if not (0 <= lo[0] <= hi[0] <= 179 and all(0 <= lo[k] <= hi[k] <= 255 for k in (1, 2))):
                    errs.append(f"classes.{c.name}.hsv: need 0 <= lower <= upper (H <= 179, S, V <= 255), "
                                f"got {lo}, {hi}")
        if not self.min_area > 0:
            errs.append(f"min_area: must be > 0 px, got {self.min_area}")
        if not 0 <= self.min_confidence <= 1:
            errs.append(f"min_confidence: must be in [0, 1], got {self.min_confidence}")
        if self.open_px < 0 or self.close_px < 0:
            errs.append(f"open_px, close_px: must be >= 0, got {self.open_px}, {self.close_px}")
        return errs


def blob_confidence(contour: np.ndarray) -> float:
    """Circularity ``4 pi A / P^2`` times the fill of the minimum enclosing circle, both
    clipped to [0, 1]: about 0.9-1 for a disc, 0.5 for a square, 0.4 for half a disc."""
    area = float(cv2.contourArea(contour))
    perim = float(cv2.arcLength(contour, True))
    if area <= 0 or perim <= 0:
        return 0.0
    _, r = cv2.minEnclosingCircle(contour)
    circ = min(1.0, 4.0 * math.pi * area / (perim * perim))
    fill = min(1.0, area / (math.pi * max(float(r), 1e-9) ** 2))
    return circ * fill


@dataclass(frozen=True)
class ColourBlobDetector:
    """The classical backend of :class:`ObjectDetector` (see the module docstring)."""

    config: ColourDetectorConfig = field(default_factory=ColourDetectorConfig)

    def __post_init__(self) -> None:
        errs = self.config.validate()
        if errs:
            raise ValueError("ColourDetectorConfig: " + "; ".join(errs))

    @property
    def classes(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.config.classes)

    @property
    def colours(self) -> Mapping[str, ColourClass]:
        return {c.name: c for c in self.config.classes}

    def detect(self, rgb: np.ndarray) -> list[Detection]:
        """Blobs of each class' colour shaped like a disc, most confident first."""
        img = np.asarray(rgb)
        if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
            raise ValueError(f"detect: need an HxWx3 uint8 RGB image, got {img.dtype} {img.shape}")
        hsv = cv2.cvtColor(img, cv2.COLOR_RGB2HSV)
        cfg = self.config
        k_open = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (cfg.open_px, cfg.open_px)) if cfg.open_px else None
        k_close = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (cfg.close_px, cfg.close_px)) if cfg.close_px else None
        out: list[Detection] = []
        for cls in cfg.classes:
            m = _hsv_mask(hsv, cls)
            if k_open is not None:
                m = cv2.morphologyEx(m, cv2.MORPH_OPEN, k_open)
            if k_close is not None:
                m = cv2.morphologyEx(m, cv2.MORPH_CLOSE, k_close)
            contours, _ = cv2.findContours(m, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
            for c in contours:
                if cv2.contourArea(c) < cfg.min_area:
                    continue
                conf = blob_confidence(c)
                if conf < cfg.min_confidence:
                    continue
                x, y, w, h = cv2.boundingRect(c)
                out.append(Detection(cls.name, conf, (int(x), int(y), int(w), int(h))))
        out.sort(key=lambda d: -d.confidence)
        log.debug("colour detector: %d objects", len(out))
        return out
