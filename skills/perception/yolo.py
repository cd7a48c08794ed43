"""ONNX backend of :class:`~mmexec.skills.perception.detector.ObjectDetector` for
YOLO-family models (YOLOv5 and YOLOv8 output layouts), run through OpenCV's DNN module.

The paper (locobot-holistic-planning-dangerous-objects, section IV-D) detects lab items
with a YOLOv5s trained on its own data set (15 classes, about 121 ms per image on the
robot's i3 CPU); the user supplies such a model as an ``.onnx`` file (Ultralytics'
``export format=onnx``) and the names of its classes. The pipeline:

1. :func:`letterbox`: resize the HxWx3 RGB image to the model's input size keeping its
   aspect ratio, centred on grey (114) padding, as Ultralytics trains and exports;
2. ``cv2.dnn.blobFromImage``: NCHW float32, RGB, scaled to [0, 1];
3. the network (OpenCV's new DNN engine, ``cv2.dnn.ENGINE_NEW``: the "auto" selection
   falls back to the classic engine, whose forward pass crashed the interpreter on
   simple graphs here; a model the new engine cannot run is refused with its message.
   The opencv-contrib-python-headless 5.0 wheel is built without ONNX Runtime);
4. :func:`decode`: the raw output to boxes, scores and class indices. Layouts:

   * ``yolov5``: ``(1, N, 5 + C)``, rows ``cx, cy, w, h, objectness, C class scores``;
     the score of a row is ``objectness * max(class scores)``;
   * ``yolov8``: ``(1, 4 + C, N)``, columns ``cx, cy, w, h, C class scores`` (no
     objectness); the score is ``max(class scores)``.

   Boxes are in pixels of the model input (the letterboxed image);
5. :func:`nms`: class-wise non-maximum suppression (``cv2.dnn.NMSBoxesBatched``);
6. :meth:`Letterbox.to_image`: boxes back into the original image, clipped to it.

The model file is checked before OpenCV parses it (:func:`read_onnx_signature`, a small
reader of ONNX's protobuf wire format): a file that is not ONNX, is truncated, has an
input that is not ``1x3xHxW`` or an output that fits neither layout for the given
classes is one :class:`ModelError` naming the file, instead of a parser crash or boxes
decoded from the wrong layout. The signature also gives the input size and, for
Ultralytics exports, the class names (metadata ``names``) when the config names none.

Not thread-safe (one ``cv2.dnn.Net`` per detector).
"""

from __future__ import annotations

import ast
import logging
import os
import stat
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Literal

import cv2
import numpy as np

from mmexec.skills.perception.detector import Detection

__all__ = [
    "PAD_VALUE",
    "Decoded",
    "Letterbox",
    "ModelError",
    "OnnxSignature",
    "TensorInfo",
    "YoloConfig",
    "YoloDetector",
    "decode",
    "infer_layout",
    "letterbox",
    "load_yolo",
    "nms",
    "read_onnx_signature",
]

log = logging.getLogger(__name__)

Layout = Literal["yolov5", "yolov8"]
#: Grey of the letterbox padding (Ultralytics' training and export value).
PAD_VALUE = 114
#: ONNX TensorProto.DataType FLOAT
_FLOAT = 1


class ModelError(ValueError):
    """A model file that cannot be used, or an output that does not fit its layout:
    ``str()`` is ``"FILE: message"``."""

    def __init__(self, path: str | os.PathLike[str], message: str) -> None:
        self.path = str(path)
        self.message = message
        super().__init__(f"{path}: {message}")


# --------------------------------------------------------------------------- letterbox


@dataclass(frozen=True)
class Letterbox:
    """How an image of ``image_size`` ``(w, h)`` [px] was fitted into the model input of
    ``input_size`` ``(W, H)``: scaled by ``scale`` and shifted by ``pad`` ``(left, top)``
    [px of the input]. Model pixel = image pixel * scale + pad."""

    scale: float
    pad: tuple[int, int]
    image_size: tuple[int, int]
    input_size: tuple[int, int]

    def to_model(self, boxes_xyxy: np.ndarray) -> np.ndarray:
        """(K, 4) ``x0, y0, x1, y1`` in image pixels -> model-input pixels."""
        b = np.asarray(boxes_xyxy, dtype=np.float64).reshape(-1, 4)
        off = np.array([self.pad[0], self.pad[1]] * 2, dtype=np.float64)
        return b * self.scale + off

    def to_image(self, boxes_xyxy: np.ndarray) -> np.ndarray:
        """(K, 4) ``x0, y0, x1, y1`` in model-input pixels -> image pixels, clipped to the
        image (``[0, w] x [0, h]``)."""
        b = np.asarray(boxes_xyxy, dtype=np.float64).reshape(-1, 4)
        off = np.array([self.pad[0], self.pad[1]] * 2, dtype=np.float64)
        out = (b - off) / self.scale
        w, h = self.image_size
        out[:, 0::2] = np.clip(out[:, 0::2], 0.0, w)
        out[:, 1::2] = np.clip(out[:, 1::2], 0.0, h)
        return out


def letterbox(rgb: np.ndarray, input_size: tuple[int, int], pad_value: int = PAD_VALUE) -> tuple[np.ndarray, Letterbox]:
    """``rgb`` (HxWx3 uint8) resized into ``input_size`` ``(W, H)`` [px] keeping its aspect
    ratio (up or down, bilinear), centred, the rest filled with ``pad_value`` grey.
    Returns the model-input image and the :class:`Letterbox` to map boxes back."""
    h, w = rgb.shape[:2]
    W, H = input_size
    r = min(W / w, H / h)
    nw, nh = max(1, round(w * r)), max(1, round(h * r))
    img = rgb if (nw, nh) == (w, h) else cv2.resize(rgb, (nw, nh), interpolation=cv2.INTER_LINEAR)
    left, top = (W - nw) // 2, (H - nh) // 2
    out = cv2.copyMakeBorder(img, top, H - nh - top, left, W - nw - left, cv2.BORDER_CONSTANT,
                             value=(pad_value, pad_value, pad_value))
    return out, Letterbox(r, (left, top), (w, h), (W, H))


# --------------------------------------------------------------------------- decoding


@dataclass(frozen=True)
class Decoded:
    """Candidate boxes of one image before NMS: ``boxes`` (K, 4) ``x0, y0, x1, y1`` [px of
    the model input], ``scores`` (K,) and ``class_ids`` (K,) int."""

    boxes: np.ndarray
    scores: np.ndarray
    class_ids: np.ndarray


def infer_layout(shape: Sequence[int | str | None], num_classes: int) -> Layout:
    """The layout whose shape ``shape`` (``(1, N, 5 + C)`` or ``(1, 4 + C, N)``) fits for
    ``num_classes`` classes. Raises ValueError when none or both fit."""
    batch_ok = len(shape) == 3 and (shape[0] in (1, None) or isinstance(shape[0], str))
    if not batch_ok:
        raise ValueError(f"output shape {tuple(shape)}: expected (1, N, 5 + C) (yolov5) or (1, 4 + C, N) (yolov8)")
    fits: list[Layout] = []
    if shape[2] == 5 + num_classes:
        fits.append("yolov5")
    if shape[1] == 4 + num_classes:
        fits.append("yolov8")
    if len(fits) != 1:
        what = "both layouts" if fits else "neither layout"
        raise ValueError(f"output shape {tuple(shape)} fits {what} for {num_classes} classes "
                         f"(yolov5: (1, N, {5 + num_classes}), yolov8: (1, {4 + num_classes}, N)); "
                         "set layout (and check the class names)")
    return fits[0]


def decode(output: np.ndarray, layout: Layout, num_classes: int, conf_threshold: float) -> Decoded:
    """Rows of a raw YOLO ``output`` (see the module doc) whose score is at least
    ``conf_threshold``, as corner boxes [px of the model input], scores and the best
    class of each. Raises ValueError when the shape does not fit ``layout``."""
    out = np.asarray(output, dtype=np.float32)
    if out.ndim == 3 and out.shape[0] == 1:
        out = out[0]
    if out.ndim != 2:
        raise ValueError(f"output shape {np.shape(output)}: expected 3 dimensions with a batch of 1")
    if layout == "yolov5":
        if out.shape[1] != 5 + num_classes:
            raise ValueError(f"output shape {np.shape(output)} does not fit yolov5 with {num_classes} classes "
                             f"(expected (1, N, {5 + num_classes}))")
        rows, cls = out[:, :4], out[:, 5:] * out[:, 4:5]
    else:
        if out.shape[0] != 4 + num_classes:
            raise ValueError(f"output shape {np.shape(output)} does not fit yolov8 with {num_classes} classes "
                             f"(expected (1, {4 + num_classes}, N))")
        rows, cls = out[:4].T, out[4:].T
    ids = np.argmax(cls, axis=1) if len(cls) else np.zeros(0, np.int64)
    scores = cls[np.arange(len(cls)), ids] if len(cls) else np.zeros(0, np.float32)
    keep = scores >= conf_threshold
    c = rows[keep].astype(np.float64)
    half = c[:, 2:4] / 2.0
    boxes = np.concatenate([c[:, :2] - half, c[:, :2] + half], axis=1)
    return Decoded(boxes, scores[keep].astype(np.float64), ids[keep].astype(np.int64))


def nms(boxes_xyxy: np.ndarray, scores: np.ndarray, class_ids: np.ndarray, iou_threshold: float,
        max_detections: int = 0) -> np.ndarray:
    """Indices of the boxes kept by class-wise non-maximum suppression (a box suppresses
    boxes of its own class overlapping it by more than ``iou_threshold``), best score
    first, at most ``max_detections`` (0: all)."""
    b = np.asarray(boxes_xyxy, dtype=np.float64).reshape(-1, 4)
    if len(b) == 0:
        return np.zeros(0, np.int64)
    xywh = np.concatenate([b[:, :2], b[:, 2:] - b[:, :2]], axis=1)
    idx = cv2.dnn.NMSBoxesBatched(xywh.tolist(), np.asarray(scores, np.float64).tolist(),
                                  np.asarray(class_ids, np.int64).astype(int).tolist(),
                                  float(np.min(scores)) - 1.0, float(iou_threshold))
    keep = np.asarray(idx, dtype=np.int64).reshape(-1)
    keep = keep[np.argsort(-np.asarray(scores)[keep], kind="stable")]
    return keep[:max_detections] if max_detections > 0 else keep


# --------------------------------------------------------------------------- ONNX signature


@dataclass(frozen=True)
class TensorInfo:
    """A graph input or output: ``name``, ONNX ``elem_type`` (1 = float32) and ``shape``
    (an int per fixed dimension, the name of a symbolic one, None when unknown)."""

    name: str
    elem_type: int
    shape: tuple[int | str | None, ...]


@dataclass(frozen=True)
class OnnxSignature:
    """What :func:`read_onnx_signature` found: the graph's ``inputs`` (initializers left
    out) and ``outputs``, and the model's ``metadata`` properties."""

    ir_version: int
    inputs: tuple[TensorInfo, ...]
    outputs: tuple[TensorInfo, ...]
    metadata: dict[str, str]


class _WireError(ValueError):
    pass


def _varint(buf: memoryview, pos: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        if pos >= len(buf):
            raise _WireError(f"truncated varint at byte {pos}")
        b = buf[pos]
        pos += 1
        value |= (b & 0x7F) << shift
        if b < 0x80:
            return value, pos
        shift += 7
        if shift > 63:
            raise _WireError(f"varint longer than 10 bytes at byte {pos}")


def _fields(buf: memoryview, base: int = 0) -> Iterator[tuple[int, int | memoryview]]:
    """``(field number, value)`` of each field of one protobuf message: an int for
    varint and fixed-width fields, a memoryview for length-delimited ones. ``base``: the
    message's offset in the file, for messages."""
    pos = 0
    while pos < len(buf):
        start = pos
        key, pos = _varint(buf, pos)
        num, wire = key >> 3, key & 7
        if num == 0:
            raise _WireError(f"field number 0 at byte {base + start}")
        if wire == 0:
            value, pos = _varint(buf, pos)
            yield num, value
        elif wire in (1, 5):
            size = 8 if wire == 1 else 4
            if pos + size > len(buf):
                raise _WireError(f"truncated field at byte {base + start}")
            yield num, int.from_bytes(buf[pos:pos + size], "little")
            pos += size
        elif wire == 2:
            size, pos = _varint(buf, pos)
            if pos + size > len(buf):
                raise _WireError(f"field {num} at byte {base + start} runs {pos + size - len(buf)} bytes past its end")
            yield num, buf[pos:pos + size]
            pos += size
        else:
            raise _WireError(f"invalid wire type {wire} at byte {base + start}")


def _text(v: int | memoryview) -> str:
    if not isinstance(v, memoryview):
        raise _WireError("expected a string field")
    return bytes(v).decode("utf-8", errors="replace")


def _sub(v: int | memoryview) -> memoryview:
    if not isinstance(v, memoryview):
        raise _WireError("expected a message field")
    return v


def _tensor_info(buf: memoryview) -> TensorInfo:
    """A ValueInfoProto (name 1, type 2 -> TypeProto.tensor_type 1 -> elem_type 1,
    shape 2 -> dim 1 -> dim_value 1 | dim_param 2)."""
    name, elem, dims = "", 0, []
    for num, v in _fields(buf):
        if num == 1:
            name = _text(v)
        elif num == 2:
            for tnum, tv in _fields(_sub(v)):
                if tnum != 1:
                    continue
                for knum, kv in _fields(_sub(tv)):
                    if knum == 1 and isinstance(kv, int):
                        elem = kv
                    elif knum == 2:
                        for dnum, dv in _fields(_sub(kv)):
                            if dnum == 1:
                                dims.append(_dim(_sub(dv)))
    return TensorInfo(name, elem, tuple(dims))


def _dim(buf: memoryview) -> int | str | None:
    for num, v in _fields(buf):
        if num == 1 and isinstance(v, int):
            return v
        if num == 2:
            return _text(v)
    return None


def read_onnx_signature(path: str | os.PathLike[str]) -> OnnxSignature:
    """The inputs, outputs and metadata of the ONNX model file at ``path``, read from its
    protobuf wire format without running it. Raises :class:`ModelError` for a missing or
    unreadable path, anything but a regular file, and bytes that are not a well-formed
    ONNX ``ModelProto`` with a graph."""
    try:
        st = os.stat(path)
        if not stat.S_ISREG(st.st_mode):
            raise ModelError(path, "not a regular file (expected an ONNX model file)")
        with open(path, "rb") as f:
            data = memoryview(f.read())
    except OSError as e:
        raise ModelError(path, f"cannot read the model: {e.strerror or e}") from None
    if not data:
        raise ModelError(path, "empty file (expected an ONNX model)")
    try:
        ir_version, graph, meta = None, None, {}
        for num, v in _fields(data):
            if num == 1 and isinstance(v, int):
                ir_version = v
            elif num == 7:
                graph = _sub(v)
            elif num == 14:
                entry = {k: _text(x) for k, x in _fields(_sub(v)) if k in (1, 2)}
                meta[entry.get(1, "")] = entry.get(2, "")
        if ir_version is None or graph is None:
            raise _WireError("no " + ("ir_version" if ir_version is None else "graph") + " field")
        init_names, inputs, outputs = set(), [], []
        for num, v in _fields(graph):
            if num == 5:
                init_names.update(_text(x) for k, x in _fields(_sub(v)) if k == 8)
            elif num == 11:
                inputs.append(_tensor_info(_sub(v)))
            elif num == 12:
                outputs.append(_tensor_info(_sub(v)))
    except _WireError as e:
        raise ModelError(path, f"not an ONNX model ({e})") from None
    return OnnxSignature(ir_version, tuple(i for i in inputs if i.name not in init_names), tuple(outputs), meta)


def _metadata_names(meta: dict[str, str]) -> tuple[str, ...] | None:
    """Class names from Ultralytics' ``names`` metadata (``{0: 'person', 1: ...}``), or
    None when absent or not a mapping of consecutive indices to names."""
    raw = meta.get("names")
    if raw is None:
        return None
    try:
        names = ast.literal_eval(raw)
    except (ValueError, SyntaxError):
        return None
    if isinstance(names, dict) and sorted(names) == list(range(len(names))):
        names = [names[i] for i in range(len(names))]
    if isinstance(names, (list, tuple)) and names and all(isinstance(n, str) for n in names):
        return tuple(names)
    return None


# --------------------------------------------------------------------------- the detector


@dataclass(frozen=True)
class YoloConfig:
    """Settings of :class:`YoloDetector`.

    ``model``: path of the ``.onnx`` file. ``classes``: the label of each class index,
    in the model's order (empty: the model's ``names`` metadata, which Ultralytics
    exports write). ``layout``: ``yolov5``, ``yolov8`` or ``auto`` (from the output
    shape and the class count; ambiguous shapes are refused). ``input_size``
    ``(W, H)`` [px]: only for a model whose input size is not fixed in the file (it
    must agree when it is). ``conf_threshold``: the lowest score kept, in [0, 1];
    ``iou_threshold``: the overlap above which NMS drops a box of the same class;
    ``max_detections`` per image."""

    model: str
    classes: tuple[str, ...] = ()
    layout: Literal["auto", "yolov5", "yolov8"] = "auto"
    input_size: tuple[int, int] | None = None
    conf_threshold: float = 0.25
    iou_threshold: float = 0.45
    max_detections: int = 100

    def validate(self) -> list[str]:
        """Problems with the settings (empty when usable); the model file is checked by
        :func:`load_yolo`."""
        errs = []
        if len(set(self.classes)) != len(self.classes):
            errs.append(f"classes: names must be unique, got {list(self.classes)}")
        if self.input_size is not None and not all(isinstance(v, int) and v > 0 for v in self.input_size):
            errs.append(f"input_size: must be two positive integers (W, H) px, got {self.input_size}")
        if not 0.0 <= self.conf_threshold <= 1.0:
            errs.append(f"conf_threshold: must be in [0, 1], got {self.conf_threshold}")
        if not 0.0 < self.iou_threshold <= 1.0:
            errs.append(f"iou_threshold: must be in (0, 1], got {self.iou_threshold}")
        if self.max_detections < 1:
            errs.append(f"max_detections: must be >= 1, got {self.max_detections}")
        return errs


class YoloDetector:
    """A YOLO model as an :class:`~mmexec.skills.perception.detector.ObjectDetector`.
    Made by :func:`load_yolo`; ``detect(rgb)`` returns the detections of one image, most
    confident first. ``layout`` and ``input_size`` ``(W, H)`` are what was resolved from
    the file and the config."""

    def __init__(self, config: YoloConfig, net: cv2.dnn.Net, classes: tuple[str, ...], layout: Layout,
                 input_size: tuple[int, int]) -> None:
        self.config = config
        self._net = net
        self._classes = classes
        self.layout = layout
        self.input_size = input_size

    @property
    def classes(self) -> tuple[str, ...]:
        return self._classes

    def infer(self, rgb: np.ndarray) -> tuple[np.ndarray, Letterbox]:
        """The raw network output for one image and the letterbox that made its input."""
        img = np.asarray(rgb)
        if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
            raise ValueError(f"detect: need an HxWx3 uint8 RGB image, got {img.dtype} {img.shape}")
        boxed, lb = letterbox(img, self.input_size)
        blob = cv2.dnn.blobFromImage(boxed, 1.0 / 255.0, self.input_size, swapRB=False, crop=False)
        try:
            self._net.setInput(blob)
            out = self._net.forward()
        except cv2.error as e:
            raise ModelError(self.config.model, f"inference failed: {_cv_message(e)}") from e
        return np.asarray(out), lb

    def detect(self, rgb: np.ndarray) -> list[Detection]:
        """Objects in one HxWx3 uint8 RGB image, most confident first; boxes ``(x, y, w,
        h)`` [px of ``rgb``]."""
        out, lb = self.infer(rgb)
        cfg = self.config
        try:
            dec = decode(out, self.layout, len(self._classes), cfg.conf_threshold)
        except ValueError as e:
            raise ModelError(cfg.model, str(e)) from None
        keep = nms(dec.boxes, dec.scores, dec.class_ids, cfg.iou_threshold, cfg.max_detections)
        boxes = np.round(lb.to_image(dec.boxes[keep])).astype(int)
        dets = [Detection(self._classes[int(c)], float(s), (int(b[0]), int(b[1]), int(b[2] - b[0]), int(b[3] - b[1])))
                for b, s, c in zip(boxes, dec.scores[keep], dec.class_ids[keep])]
        log.debug("yolo: %d candidates, %d detections", len(dec.scores), len(dets))
        return [d for d in dets if d.box[2] > 0 and d.box[3] > 0]


def _cv_message(e: cv2.error) -> str:
    """The useful part of an OpenCV error (``... error: (-215:...) what in function ...``)."""
    text = str(e).strip()
    return text.split(" error: ", 1)[-1] if " error: " in text else text


def _input_size(path: str, sig: OnnxSignature, given: tuple[int, int] | None) -> tuple[int, int]:
    if len(sig.inputs) != 1:
        raise ModelError(path, f"expected one image input, the model has {len(sig.inputs)}: "
                               f"{[i.name for i in sig.inputs]}")
    inp = sig.inputs[0]
    shape = inp.shape
    if len(shape) != 4 or shape[1] != 3 or inp.elem_type != _FLOAT:
        raise ModelError(path, f"input {inp.name!r}: expected a float32 1x3xHxW image, got shape {shape} "
                               f"(element type {inp.elem_type})")
    h, w = shape[2], shape[3]
    if isinstance(h, int) and isinstance(w, int):
        if given is not None and tuple(given) != (w, h):
            raise ModelError(path, f"input_size {tuple(given)} differs from the model's fixed input {(w, h)} (W, H)")
        return (w, h)
    if given is None:
        raise ModelError(path, f"input {inp.name!r} has no fixed size ({shape}): set input_size (W, H)")
    return (int(given[0]), int(given[1]))


def load_yolo(config: YoloConfig) -> YoloDetector:
    """Check ``config`` and its model file (:func:`read_onnx_signature`), resolve the class
    names, layout and input size, and load the network. Raises ValueError for bad
    settings and :class:`ModelError` (``"FILE: message"``) for a model that cannot be
    used."""
    errs = config.validate()
    if errs:
        raise ValueError("YoloConfig: " + "; ".join(errs))
    path = config.model
    sig = read_onnx_signature(path)
    size = _input_size(path, sig, config.input_size)
    classes = config.classes or _metadata_names(sig.metadata)
    if not classes:
        raise ModelError(path, "no class names: the model has no 'names' metadata; set classes")
    if len(sig.outputs) < 1:
        raise ModelError(path, "the graph has no output")
    out_shape = sig.outputs[0].shape
    static = len(out_shape) == 3 and all(isinstance(d, int) for d in out_shape[1:])
    layout: Layout
    try:
        if config.layout == "auto":
            layout = infer_layout(out_shape, len(classes))
        else:
            layout = config.layout
            if static:
                decode(np.zeros((1, *(int(d) for d in out_shape[1:])), np.float32), layout, len(classes), 1.0)
    except ValueError as e:
        raise ModelError(path, f"output {sig.outputs[0].name!r}: {e}") from None
    try:
        net = cv2.dnn.readNetFromONNX(str(path), engine=cv2.dnn.ENGINE_NEW)
    except cv2.error as e:
        raise ModelError(path, f"OpenCV cannot load the model: {_cv_message(e)}") from None
    log.info("yolo: %s, %s layout, input %dx%d, %d classes", path, layout, size[0], size[1], len(classes))
    return YoloDetector(config, net, tuple(classes), layout, size)
