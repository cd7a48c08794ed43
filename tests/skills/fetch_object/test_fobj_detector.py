"""The classical parts detector of the sim object set (skills/fetch_object/detector.py):
synthetic shaded parts, and frames rendered by the simulator with the grasp point from
the box and depth checked against the true centre of mass."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mmexec.skills.fetch_object.detector import PartsDetector, make_detector
from mmexec.skills.perception.grasp_point import estimate_grasp

REPO = Path(__file__).resolve().parents[3]
YELLOW, CYAN, GREEN = (0.95, 0.8, 0.08), (0.08, 0.8, 0.9), (0.08, 0.7, 0.2)


def _paint(img: np.ndarray, box: tuple[int, int, int, int], rgb: tuple[float, float, float], shade: float) -> None:
    x, y, w, h = box
    img[y:y + h, x:x + w] = (np.array(rgb) * 255 * shade).astype(np.uint8)


def _scene() -> np.ndarray:
    rng = np.random.default_rng(0)
    img = rng.integers(90, 140, (240, 320, 3)).astype(np.uint8)  # grey clutter
    img[:, :, 0] = img[:, :, 1]  # unsaturated
    return img


def test_a_two_colour_tool_is_one_box_over_both_parts() -> None:
    img = _scene()
    _paint(img, (40, 100, 60, 20), YELLOW, 0.9)   # handle
    _paint(img, (100, 102, 55, 16), CYAN, 0.7)   # blade, touching it, in shade
    _paint(img, (200, 60, 70, 18), GREEN, 0.8)   # a pen elsewhere
    dets = {d.label: d for d in PartsDetector().detect(img)}
    assert set(dets) == {"screwdriver", "pen"}
    x, y, w, h = dets["screwdriver"].box
    assert (x, x + w) == (40, 155) and (y, y + h) == (100, 120)
    assert dets["screwdriver"].confidence > 0.8 and dets["pen"].confidence > 0.9


def test_a_tool_showing_only_its_main_colour_is_trusted_less() -> None:
    img = _scene()
    _paint(img, (40, 100, 60, 20), YELLOW, 0.9)
    (d,) = PartsDetector().detect(img)
    assert d.label == "screwdriver" and d.confidence == pytest.approx(0.6, abs=0.05)
    assert PartsDetector().detect(_scene()) == []  # clutter alone: nothing


def test_make_detector_names_a_bad_model_file(tmp_path: Path) -> None:
    bad = tmp_path / "model.onnx"
    bad.write_bytes(b"not a model")
    with pytest.raises(ValueError, match="model.onnx"):
        make_detector("onnx", model=str(bad))
    assert make_detector("colour").classes == ("box", "cylinder", "screwdriver", "pliers", "pen")


@pytest.mark.slow
def test_rendered_table_objects_are_found_and_their_grasp_points_are_within_a_centimetre() -> None:
    from mmexec.drivers.interfaces import Pose2D
    from mmexec.executive.config import build_robot, load_config
    from mmexec.sim.objects import centre_of_mass, object_frame

    robot = build_robot(load_config(REPO / "config" / "locobot_objects_sim.yaml"), seed=0)
    try:
        pose = Pose2D(2.62, 1.5, -1.5708)  # the catalogue's table_front
        robot.core.place_base(pose)
        robot.base.reset_estimate(pose)
        robot.spin(0.5)
        frame = robot.camera.frame()
        assert frame is not None
        dets = {d.label: d for d in PartsDetector().detect(frame.rgb)}
        assert {"pen", "screwdriver"} <= set(dets)
        sizes = {"pen": (0.14, 0.04, 0.04), "screwdriver": (0.19, 0.04, 0.04)}
        for name in ("pen", "screwdriver"):
            obj = next(o for o in robot.world.spec.objects if o.name == name)
            T = object_frame(robot.cid, robot.scene_handles.items[name], obj.model)
            com = (T @ np.array([*centre_of_mass(obj.model), 1.0]))[:3]
            g = estimate_grasp(frame, dets[name].box, size=sizes[name])
            assert np.linalg.norm(g.centre - com) < 0.01, (name, g.centre, com)
            assert abs(g.yaw) < 0.1  # both lie along the table's x
    finally:
        robot.close()
