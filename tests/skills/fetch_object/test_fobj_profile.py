"""The fetch_object profile section picks the detector (the classical one, or the user's
ONNX model) and the catalogue, checked against the named poses and the detector's classes."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import onnx
import pytest
from onnx import TensorProto, helper, numpy_helper

from mmexec.skills.base import SkillContext, SkillFailure
from mmexec.skills.fetch_object.detector import PartsDetector
from mmexec.skills.fetch_object.skills import catalogue, detector
from mmexec.skills.perception.yolo import YoloDetector

CLASSES = ["screwdriver", "pliers", "pen"]


def _model(path: Path) -> Path:
    """A YOLOv8-layout model (1, 4 + 3, 20) whose output is a constant: one screwdriver box
    (cx, cy, w, h = 320, 320, 64, 32 in the 640 input) with score 0.9."""
    base = np.zeros((1, 4 + len(CLASSES), 20), np.float32)
    base[0, :4, 0] = (320, 320, 64, 32)
    base[0, 4, 0] = 0.9
    inp = helper.make_tensor_value_info("images", TensorProto.FLOAT, [1, 3, 640, 640])
    out = helper.make_tensor_value_info("output0", TensorProto.FLOAT, list(base.shape))
    nodes = [helper.make_node("ReduceMax", ["images", "axes"], ["m4"], keepdims=1),
             helper.make_node("Reshape", ["m4", "shape3"], ["m"]),
             helper.make_node("Mul", ["m", "zero"], ["z"]),
             helper.make_node("Add", ["base", "z"], ["output0"])]
    consts = {"axes": np.array([0, 1, 2, 3], np.int64), "shape3": np.array([1, 1, 1], np.int64),
              "zero": np.array([0.0], np.float32), "base": base}
    graph = helper.make_graph(nodes, "const", [inp], [out], [numpy_helper.from_array(v, k) for k, v in consts.items()])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 18)])
    onnx.checker.check_model(model)
    path.write_bytes(model.SerializeToString())
    return path


def _ctx(fetch_object: dict[str, Any]) -> SkillContext:
    profile = {"places": {"bench": [1.0, 1.0, 0.0]}, "fetch_object": fetch_object}
    return SkillContext(robot=SimpleNamespace(), clock=SimpleNamespace(now=lambda: 0.0),  # type: ignore[arg-type]
                        profile=profile)


def _catalogue(tmp_path: Path, cls: str = "screwdriver") -> Path:
    path = tmp_path / "items.yaml"
    path.write_text(f"items:\n  sd:\n    detector_class: {cls}\n    places: [bench]\n    size: [0.19, 0.04, 0.04]\n")
    return path


def test_the_profile_picks_the_users_onnx_model(tmp_path: Path) -> None:
    model = _model(tmp_path / "tools.onnx")
    ctx = _ctx({"catalogue": str(_catalogue(tmp_path)),
                "detector": {"backend": "onnx", "model": str(model), "classes": CLASSES}})
    det = detector(ctx)
    assert isinstance(det, YoloDetector) and det.classes == tuple(CLASSES)
    (d,) = det.detect(np.zeros((480, 640, 3), np.uint8))
    assert d.label == "screwdriver" and d.confidence == pytest.approx(0.9)
    assert d.box == (288, 224, 64, 32)  # the letterbox's 80 px of padding taken off
    assert catalogue(ctx).item("sd").detector_class == "screwdriver"


def test_the_colour_detector_by_default_and_the_catalogue_checked_against_it(tmp_path: Path) -> None:
    ctx = _ctx({"catalogue": str(_catalogue(tmp_path, "screwdrivr"))})
    assert isinstance(detector(ctx), PartsDetector)
    with pytest.raises(SkillFailure) as e:
        catalogue(ctx)
    assert "did you mean 'screwdriver'" in e.value.reason and "items.yaml:" in e.value.reason


def test_a_bad_model_file_is_one_line_naming_it(tmp_path: Path) -> None:
    bad = tmp_path / "broken.onnx"
    bad.write_bytes(b"\x08\x01garbage")
    ctx = _ctx({"catalogue": str(_catalogue(tmp_path)), "detector": {"backend": "onnx", "model": str(bad)}})
    with pytest.raises(SkillFailure) as e:
        detector(ctx)
    assert e.value.reason.startswith("profile.fetch_object.detector: ") and "broken.onnx" in e.value.reason
    assert "\n" not in e.value.reason
