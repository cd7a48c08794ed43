"""The ONNX YOLO backend: decoding against hand-computed outputs, letterbox, NMS, the
model-file checks, and tiny ONNX graphs (built here with onnx.helper, no download) run
end to end through cv2.dnn in the YOLOv5 and YOLOv8 output layouts."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import onnx
import pytest
from onnx import TensorProto, helper, numpy_helper

from mmexec.skills.perception.detector import Detection, ObjectDetector
from mmexec.skills.perception.yolo import (
    PAD_VALUE,
    Letterbox,
    ModelError,
    YoloConfig,
    decode,
    infer_layout,
    letterbox,
    load_yolo,
    nms,
    read_onnx_signature,
)

CLASSES = ("screwdriver", "plier", "box")

# --------------------------------------------------------------------------- decoding


def test_decode_yolov5_hand_computed() -> None:
    out = np.array([[
        [100.0, 50.0, 20.0, 10.0, 0.8, 0.5, 0.9, 0.1],   # score 0.8 * 0.9 = 0.72, class 1
        [300.0, 200.0, 40.0, 60.0, 0.5, 0.6, 0.2, 0.3],  # 0.5 * 0.6 = 0.30, class 0
        [10.0, 10.0, 4.0, 4.0, 0.2, 0.9, 0.9, 0.9],      # 0.18 < 0.25: dropped
        [50.0, 60.0, 8.0, 6.0, 0.9, 0.1, 0.1, 0.27],     # 0.243 < 0.25: dropped
    ]], np.float32)
    d = decode(out, "yolov5", 3, 0.25)
    np.testing.assert_allclose(d.boxes, [[90, 45, 110, 55], [280, 170, 320, 230]])
    np.testing.assert_allclose(d.scores, [0.72, 0.30], rtol=1e-6)
    assert d.class_ids.tolist() == [1, 0]


def test_decode_yolov8_hand_computed() -> None:
    rows = np.array([
        [100.0, 50.0, 20.0, 10.0, 0.1, 0.9, 0.2],   # class 1, 0.9
        [300.0, 200.0, 40.0, 60.0, 0.2, 0.1, 0.4],  # class 2, 0.4
        [10.0, 10.0, 4.0, 4.0, 0.2, 0.1, 0.1],      # 0.2: dropped
    ], np.float32)
    d = decode(rows.T[None], "yolov8", 3, 0.25)
    np.testing.assert_allclose(d.boxes, [[90, 45, 110, 55], [280, 170, 320, 230]])
    np.testing.assert_allclose(d.scores, [0.9, 0.4], rtol=1e-6)
    assert d.class_ids.tolist() == [1, 2]


def test_decode_nothing_above_threshold_is_empty() -> None:
    d = decode(np.zeros((1, 5, 8), np.float32), "yolov5", 3, 0.25)
    assert d.boxes.shape == (0, 4) and d.scores.shape == (0,) and d.class_ids.shape == (0,)


@pytest.mark.parametrize(("shape", "layout", "message"), [
    ((1, 10, 9), "yolov5", r"does not fit yolov5 with 3 classes \(expected \(1, N, 8\)\)"),
    ((1, 8, 10), "yolov8", r"does not fit yolov8 with 3 classes \(expected \(1, 7, N\)\)"),
    ((2, 10, 8), "yolov5", r"expected 3 dimensions with a batch of 1"),
    ((10, 8, 1, 1), "yolov5", r"expected 3 dimensions"),
])
def test_decode_wrong_shape_is_one_clear_error(shape: tuple[int, ...], layout: str, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        decode(np.zeros(shape, np.float32), layout, 3, 0.25)  # type: ignore[arg-type]


def test_infer_layout() -> None:
    assert infer_layout((1, 25200, 85), 80) == "yolov5"
    assert infer_layout((1, 84, 8400), 80) == "yolov8"
    assert infer_layout(("batch", 84, "anchors"), 80) == "yolov8"
    with pytest.raises(ValueError, match="fits both layouts for 2 classes"):
        infer_layout((1, 6, 7), 2)
    with pytest.raises(ValueError, match="fits neither layout for 3 classes"):
        infer_layout((1, 25200, 85), 3)
    with pytest.raises(ValueError, match=r"expected \(1, N, 5 \+ C\)"):
        infer_layout((25200, 85), 80)


# --------------------------------------------------------------------------- letterbox


def test_letterbox_landscape_pads_top_and_bottom_grey() -> None:
    img = np.full((480, 640, 3), 200, np.uint8)
    out, lb = letterbox(img, (640, 640))
    assert out.shape == (640, 640, 3)
    assert lb == Letterbox(1.0, (0, 80), (640, 480), (640, 640))
    assert (out[:80] == PAD_VALUE).all() and (out[560:] == PAD_VALUE).all() and (out[80:560] == 200).all()


def test_letterbox_portrait_upscaled_pads_left_and_right() -> None:
    img = np.full((200, 100, 3), 10, np.uint8)
    out, lb = letterbox(img, (320, 320))
    assert lb.scale == pytest.approx(1.6) and lb.pad == (80, 0)
    assert (out[:, :80] == PAD_VALUE).all() and (out[:, 80:240] == 10).all() and (out[:, 240:] == PAD_VALUE).all()


@pytest.mark.parametrize(("image_size", "input_size"), [((640, 480), (640, 640)), ((640, 480), (320, 256)),
                                                         ((333, 517), (416, 416)), ((100, 60), (640, 384))])
def test_letterbox_round_trip(image_size: tuple[int, int], input_size: tuple[int, int]) -> None:
    w, h = image_size
    _, lb = letterbox(np.zeros((h, w, 3), np.uint8), input_size)
    rng = np.random.default_rng(3)
    x0, y0 = rng.uniform(0, w / 2, 20), rng.uniform(0, h / 2, 20)
    boxes = np.stack([x0, y0, x0 + rng.uniform(1, w / 2, 20), y0 + rng.uniform(1, h / 2, 20)], axis=1)
    model = lb.to_model(boxes)
    W, H = input_size
    assert (model[:, 0::2] >= lb.pad[0] - 1e-9).all() and (model[:, 0::2] <= W - lb.pad[0] + 1).all()
    assert (model[:, 1::2] >= lb.pad[1] - 1e-9).all() and (model[:, 1::2] <= H - lb.pad[1] + 1).all()
    np.testing.assert_allclose(lb.to_image(model), boxes, atol=1e-9)


def test_letterbox_to_image_clips_to_the_image() -> None:
    _, lb = letterbox(np.zeros((480, 640, 3), np.uint8), (640, 640))
    np.testing.assert_allclose(lb.to_image(np.array([[-10.0, 40.0, 700.0, 600.0]])), [[0, 0, 640, 480]])


# --------------------------------------------------------------------------- NMS


def test_nms_suppresses_within_a_class_only() -> None:
    boxes = np.array([[0, 0, 100, 100], [5, 5, 105, 105], [0, 0, 100, 100], [200, 200, 250, 260],
                      [210, 205, 252, 262]], float)
    scores = np.array([0.6, 0.9, 0.7, 0.5, 0.4])
    ids = np.array([0, 0, 1, 0, 0])
    keep = nms(boxes, scores, ids, 0.45)
    # box 1 beats box 0 (IoU 0.82, same class); box 2 is another class; box 3 beats 4
    assert keep.tolist() == [1, 2, 3]
    assert nms(boxes, scores, ids, 0.45, max_detections=2).tolist() == [1, 2]
    assert nms(boxes, scores, ids, 0.95).tolist() == [1, 2, 0, 3, 4]
    assert nms(np.zeros((0, 4)), np.zeros(0), np.zeros(0, int), 0.45).tolist() == []


# --------------------------------------------------------------------------- tiny ONNX models

MODEL_IN = (320, 320)  # W, H


def _expected_model_rows(lb: Letterbox, image_boxes: list[tuple[float, float, float, float]]) -> np.ndarray:
    """``cx, cy, w, h`` [px of the model input] of boxes ``(x, y, w, h)`` in the image."""
    xyxy = np.array([(x, y, x + w, y + h) for x, y, w, h in image_boxes], float)
    m = lb.to_model(xyxy)
    return np.stack([(m[:, 0] + m[:, 2]) / 2, (m[:, 1] + m[:, 3]) / 2, m[:, 2] - m[:, 0], m[:, 3] - m[:, 1]], axis=1)


#: image boxes (x, y, w, h) [px of a 640x480 image], class id, class score (and objectness 1)
SCENE = [
    ((100.0, 120.0, 80.0, 60.0), 0, 0.90),   # kept
    ((104.0, 122.0, 80.0, 60.0), 0, 0.80),   # same class, IoU 0.87 with the first: suppressed
    ((104.0, 122.0, 80.0, 60.0), 2, 0.70),   # same place, another class: kept
    ((400.0, 300.0, 120.0, 100.0), 1, 0.60),  # kept
    ((500.0, 40.0, 60.0, 60.0), 1, 0.10),    # below the threshold
]


def _scene_output(layout: str, num_anchors: int = 12) -> np.ndarray:
    """The raw output a model should give for :data:`SCENE` on a 640x480 image, with
    empty (all zero) anchors after the listed ones."""
    _, lb = letterbox(np.zeros((480, 640, 3), np.uint8), MODEL_IN)
    rows = np.zeros((num_anchors, 5 + len(CLASSES)), np.float32)
    rows[: len(SCENE), :4] = _expected_model_rows(lb, [b for b, _, _ in SCENE])
    for i, (_, cls, score) in enumerate(SCENE):
        rows[i, 4] = 1.0
        rows[i, 5 + cls] = score
    if layout == "yolov5":
        return rows[None]
    return np.delete(rows, 4, axis=1).T[None].copy()


def _build_model(path: Path, base: np.ndarray, *, input_shape: list[int | str] | None = None,
                 names: str | None = None) -> Path:
    """An ONNX model whose output is ``base`` with its score entries scaled by the largest
    value of input channel 0 (R): 1 for an image with a pure red pixel fed as RGB /255, 0
    for one fed as BGR. Coordinates pass through unchanged."""
    mask = np.zeros_like(base)
    if base.shape[2] == 5 + len(CLASSES):  # yolov5: objectness and class columns
        mask[..., 4:] = 1.0
    else:  # yolov8 (1, 4 + C, N): the class rows
        mask[:, 4:, :] = 1.0
    shape = input_shape or [1, 3, MODEL_IN[1], MODEL_IN[0]]
    inp = helper.make_tensor_value_info("images", TensorProto.FLOAT, shape)
    out = helper.make_tensor_value_info("output0", TensorProto.FLOAT, list(base.shape))
    nodes = [
        helper.make_node("Slice", ["images", "c0", "c1", "c_axis"], ["red"]),
        helper.make_node("ReduceMax", ["red", "all_axes"], ["red_max4"], keepdims=1),
        helper.make_node("Reshape", ["red_max4", "shape3"], ["red_max"]),
        helper.make_node("Sub", ["red_max", "one"], ["delta"]),
        helper.make_node("Mul", ["mask", "delta"], ["masked"]),
        helper.make_node("Add", ["masked", "one"], ["factor"]),
        helper.make_node("Mul", ["base", "factor"], ["output0"]),
    ]
    consts = {
        "c0": np.array([0], np.int64), "c1": np.array([1], np.int64), "c_axis": np.array([1], np.int64),
        "all_axes": np.array([0, 1, 2, 3], np.int64), "shape3": np.array([1, 1, 1], np.int64),
        "one": np.array([1.0], np.float32), "mask": mask, "base": base.astype(np.float32),
    }
    graph = helper.make_graph(nodes, "tiny_yolo", [inp], [out],
                              [numpy_helper.from_array(v, k) for k, v in consts.items()])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 18)])
    if names is not None:
        helper.set_model_props(model, {"names": names})
    onnx.checker.check_model(model)
    path.write_bytes(model.SerializeToString())
    return path


def _red_image() -> np.ndarray:
    img = np.zeros((480, 640, 3), np.uint8)
    img[..., 0] = 255
    return img


@pytest.mark.parametrize("layout", ["yolov5", "yolov8"])
@pytest.mark.parametrize("configured", ["auto", "explicit"])
def test_end_to_end_through_cv2_dnn(tmp_path: Path, layout: str, configured: str) -> None:
    model = _build_model(tmp_path / f"{layout}.onnx", _scene_output(layout))
    det = load_yolo(YoloConfig(str(model), classes=CLASSES,
                               layout="auto" if configured == "auto" else layout))  # type: ignore[arg-type]
    as_interface: ObjectDetector = det  # the interface a skill holds (checked by mypy)
    assert det.layout == layout and det.input_size == MODEL_IN and det.classes == CLASSES
    raw, lb = det.infer(_red_image())
    np.testing.assert_allclose(raw, _scene_output(layout), atol=1e-4)
    assert lb.scale == 0.5 and lb.pad == (0, 40)
    assert as_interface.detect(_red_image()) == [
        Detection("screwdriver", pytest.approx(0.90), (100, 120, 80, 60)),
        Detection("box", pytest.approx(0.70), (104, 122, 80, 60)),
        Detection("plier", pytest.approx(0.60), (400, 300, 120, 100)),
    ]


def test_end_to_end_feeds_rgb_scaled_to_one(tmp_path: Path) -> None:
    """The model sees the image's R channel first, scaled by 1/255: a pure blue frame
    filling the input (no padding) makes every score 0."""
    det = load_yolo(YoloConfig(str(_build_model(tmp_path / "m.onnx", _scene_output("yolov5"))), classes=CLASSES))
    blue = np.zeros((320, 320, 3), np.uint8)
    blue[..., 2] = 255
    raw, _ = det.infer(blue)
    assert np.all(raw[0, :, 4:] == 0)
    assert det.detect(blue) == []


def test_class_names_from_the_model_metadata(tmp_path: Path) -> None:
    path = _build_model(tmp_path / "m.onnx", _scene_output("yolov8"),
                        names="{0: 'screwdriver', 1: 'plier', 2: 'box'}")
    det = load_yolo(YoloConfig(str(path)))
    assert det.classes == CLASSES and det.layout == "yolov8"


def test_dynamic_input_needs_input_size(tmp_path: Path) -> None:
    path = _build_model(tmp_path / "dyn.onnx", _scene_output("yolov5"), input_shape=[1, 3, "height", "width"])
    with pytest.raises(ModelError, match=r"dyn.onnx: input 'images' has no fixed size .*: set input_size"):
        load_yolo(YoloConfig(str(path), classes=CLASSES))
    det = load_yolo(YoloConfig(str(path), classes=CLASSES, input_size=MODEL_IN))
    assert det.detect(_red_image())[0] == Detection("screwdriver", pytest.approx(0.9), (100, 120, 80, 60))


# --------------------------------------------------------------------------- bad model files


def test_signature_of_a_built_model(tmp_path: Path) -> None:
    sig = read_onnx_signature(_build_model(tmp_path / "m.onnx", _scene_output("yolov5"), names="{0: 'a'}"))
    assert [(t.name, t.elem_type, t.shape) for t in sig.inputs] == [("images", 1, (1, 3, 320, 320))]
    assert [(t.name, t.shape) for t in sig.outputs] == [("output0", (1, 12, 8))]
    assert sig.metadata == {"names": "{0: 'a'}"} and sig.ir_version > 0


@pytest.mark.parametrize(("content", "message"), [
    (b"", "empty file"),
    (b"# not a model\nname: yolo\n", "not an ONNX model"),
    (b"\xff\xd8\xff\xe0\x00\x10JFIF\x00", "not an ONNX model"),
    (b"\x08\x07", r"not an ONNX model \(no graph field\)"),
])
def test_not_an_onnx_file_is_one_located_error(tmp_path: Path, content: bytes, message: str) -> None:
    path = tmp_path / "model.onnx"
    path.write_bytes(content)
    with pytest.raises(ModelError, match=f"^{path}: {message}"):
        load_yolo(YoloConfig(str(path), classes=CLASSES))


def test_truncated_model_is_refused_before_opencv_parses_it(tmp_path: Path) -> None:
    good = _build_model(tmp_path / "m.onnx", _scene_output("yolov5")).read_bytes()
    cut = tmp_path / "cut.onnx"
    cut.write_bytes(good[: len(good) - 40])
    with pytest.raises(ModelError, match=r"cut.onnx: not an ONNX model \(field 7 at byte \d+ runs \d+ bytes past its end\)"):
        load_yolo(YoloConfig(str(cut), classes=CLASSES))


def test_missing_file_and_directory(tmp_path: Path) -> None:
    with pytest.raises(ModelError, match=r"nope.onnx: cannot read the model: No such file"):
        load_yolo(YoloConfig(str(tmp_path / "nope.onnx"), classes=CLASSES))
    with pytest.raises(ModelError, match=r": not a regular file"):
        load_yolo(YoloConfig(str(tmp_path), classes=CLASSES))


def test_output_that_fits_no_layout_for_the_classes(tmp_path: Path) -> None:
    path = _build_model(tmp_path / "m.onnx", _scene_output("yolov5"))
    with pytest.raises(ModelError, match=r"m.onnx: output 'output0': output shape \(1, 12, 8\) fits neither layout "
                                         r"for 4 classes"):
        load_yolo(YoloConfig(str(path), classes=(*CLASSES, "pen")))
    with pytest.raises(ModelError, match=r"does not fit yolov8 with 3 classes"):
        load_yolo(YoloConfig(str(path), classes=CLASSES, layout="yolov8"))


def test_input_that_is_not_an_image(tmp_path: Path) -> None:
    path = _build_model(tmp_path / "m.onnx", _scene_output("yolov5"), input_shape=[1, 1, 320, 320])
    with pytest.raises(ModelError, match=r"input 'images': expected a float32 1x3xHxW image, got shape \(1, 1, 320, 320\)"):
        load_yolo(YoloConfig(str(path), classes=CLASSES))


def test_no_class_names_and_input_size_disagreeing(tmp_path: Path) -> None:
    path = _build_model(tmp_path / "m.onnx", _scene_output("yolov5"))
    with pytest.raises(ModelError, match="no class names: the model has no 'names' metadata; set classes"):
        load_yolo(YoloConfig(str(path)))
    with pytest.raises(ModelError, match=r"input_size \(640, 640\) differs from the model's fixed input \(320, 320\)"):
        load_yolo(YoloConfig(str(path), classes=CLASSES, input_size=(640, 640)))


def test_bad_settings_are_listed_together() -> None:
    with pytest.raises(ValueError, match=r"YoloConfig: classes: names must be unique.*; conf_threshold: must be in "
                                         r"\[0, 1\], got 1.5; iou_threshold: must be in \(0, 1\], got 0.0"):
        load_yolo(YoloConfig("m.onnx", classes=("a", "a"), conf_threshold=1.5, iou_threshold=0.0))


def test_detect_refuses_a_non_rgb_image(tmp_path: Path) -> None:
    det = load_yolo(YoloConfig(str(_build_model(tmp_path / "m.onnx", _scene_output("yolov5"))), classes=CLASSES))
    with pytest.raises(ValueError, match=r"need an HxWx3 uint8 RGB image, got float64 \(480, 640\)"):
        det.detect(np.zeros((480, 640)))
