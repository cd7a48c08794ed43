"""The scan skill on the mock backend: four head poses, two predictions each, fused in map.

The mock's camera is replaced by one that renders an exact RGB-D view of a few objects on
the floor (skills.perception.synthetic_objects) from the head's current pose, with
stereo-like depth noise, and the detector is a plain colour-threshold one: what the scan
fuses is measured on images, not scripted."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from mmexec.drivers.interfaces import CameraFrame, CameraIntrinsics, Pose2D
from mmexec.drivers.mock import MockCamera, MockRobot
from mmexec.skills.base import FailureKind, SkillContext, SkillRun, SkillStatus, run_skill
from mmexec.skills.perception.detector import Detection
from mmexec.skills.perception.scan import (
    WORLD_OBJECT_DETECTOR,
    WORLD_SCAN,
    Prediction,
    ScanResult,
    fuse,
    scan,
)
from mmexec.skills.perception.synthetic_objects import SceneObject, render_scene, spoil_depth

RED, BLUE = (210, 30, 30), (30, 40, 210)
#: two red boxes far apart (two objects of one class) and a blue cylinder, on the floor
SCENE = (
    SceneObject("box", (1.5, 0.75, 0.05), (0.10, 0.10, 0.10), yaw=0.3, colour=RED),
    SceneObject("box", (1.4, -0.45, 0.05), (0.10, 0.10, 0.10), colour=RED),
    SceneObject("cylinder", (1.3, 0.05, 0.06), (0.08, 0.08, 0.12), colour=BLUE),
)
HEAD_POSES = [[0.6, 0.5], [0.2, 0.5], [-0.2, 0.5], [-0.6, 0.5]]
BASE = Pose2D(0.3, -0.2, 0.1)  # the robot somewhere in map, turned a little


class RenderingCamera(MockCamera):
    """The mock camera on the mock head, rendering SCENE exactly from where it is now."""

    def __init__(self, robot: MockRobot, seed: int = 0) -> None:
        super().__init__(robot.clock, robot.base, head=robot.head, width=320, height=240, hfov=1.0)
        self.rng = np.random.default_rng(seed)
        self.captured: list[CameraFrame] = []

    def frame(self) -> CameraFrame | None:
        self.calls += 1
        T_map_base = self._base.pose.matrix()
        T_base_cam = self.pose_in_base()
        view = render_scene(SCENE, T_map_base @ T_base_cam, self.intrinsics)
        depth = spoil_depth(view.depth, self.rng, holes=0.0, flying=0.0)
        f = CameraFrame(view.rgb, depth, self.intrinsics, self._clock.now(), T_base_cam, T_map_base)
        self.captured.append(f)
        return f


class ColourBoxes:
    """A detector of saturated red and blue regions: one box per connected region, the
    confidence higher the nearer the image centre (so views differ)."""

    classes = ("red", "blue")

    def detect(self, rgb: np.ndarray) -> list[Detection]:
        h, w = rgb.shape[:2]
        out = []
        for label, ch in (("red", 0), ("blue", 2)):
            others = [c for c in range(3) if c != ch]
            mask = ((rgb[..., ch].astype(int) - rgb[..., others].max(axis=-1)) > 60).astype(np.uint8)
            n, _, stats, cent = cv2.connectedComponentsWithStats(mask)
            for k in range(1, n):
                x, y, bw, bh, area = (int(v) for v in stats[k])
                if area < 20:
                    continue
                off = math.hypot(cent[k][0] - w / 2, cent[k][1] - h / 2) / math.hypot(w / 2, h / 2)
                out.append(Detection(label, round(0.95 - 0.5 * off, 4), (x, y, bw, bh)))
        return sorted(out, key=lambda d: -d.confidence)


@pytest.fixture
def robot() -> MockRobot:
    r = MockRobot(capabilities={"base", "camera", "head"},
                  profile={"scan": {"head_poses": HEAD_POSES, "settle_time": 0.1}})
    r.base.pose = BASE
    r.camera = RenderingCamera(r)
    return r


@pytest.fixture
def ctx(robot: MockRobot) -> SkillContext:
    events: list[tuple[str, dict]] = []
    c = SkillContext.for_robot(robot, emit=lambda e, **f: events.append((e, f)))
    c.world[WORLD_OBJECT_DETECTOR] = ColourBoxes()
    c.world["events"] = events
    return c


def test_four_head_poses_two_predictions_fused_in_map(robot: MockRobot, ctx: SkillContext) -> None:
    run = run_skill(scan.spec, ctx, {}, step=lambda: robot.spin(0.05))
    assert run.status is SkillStatus.SUCCESS, run.failure
    out = run.outputs
    assert out["views"] == 4 and out["predictions"] == 8
    # the head went to the four poses, then back home
    assert robot.head.targets == [tuple(p) for p in HEAD_POSES] + [robot.head.home]
    assert (robot.head.state().pan, robot.head.state().tilt) == robot.head.home
    objects = out["objects"]
    assert sorted(o["label"] for o in objects) == ["blue", "red", "red"]
    truth = {"red": [np.array(o.centre) for o in SCENE if o.colour == RED],
             "blue": [np.array(SCENE[2].centre)]}
    for o in objects:
        err = min(np.linalg.norm(np.array(o["position"]) - t) for t in truth[o["label"]])
        assert err < 0.03, o
        assert o["seen"] >= 2 and o["spread"] < 0.05  # several views agree in map
    # confidence and position are the means over the object's predictions
    result: ScanResult = ctx.world[WORLD_SCAN]
    for obj in result.objects:
        assert obj.confidence == pytest.approx(np.mean([p.confidence for p in obj.predictions]))
        assert np.allclose(obj.position, np.mean([p.position for p in obj.predictions], axis=0))
        assert obj.frame is obj.best.frame and obj.best.confidence == max(p.confidence for p in obj.predictions)
        assert obj.last_frame is obj.predictions[-1].frame
    # the views differ: each red box is seen from its side of the scan only
    views_of = {tuple(np.round(o.position, 1)): {p.view for p in o.predictions} for o in result.objects}
    assert len({frozenset(v) for v in views_of.values()}) > 1
    events = [e for e, _ in ctx.world["events"]]
    assert events.count("scan_view") == 4 and events[-1] == "scan_done"


def test_frames_carry_the_head_pose_they_were_taken_at(robot: MockRobot, ctx: SkillContext) -> None:
    run_skill(scan.spec, ctx, {}, step=lambda: robot.spin(0.05))
    frames = robot.camera.captured
    assert len(frames) == 8
    model = robot.head.kinematics
    for k, f in enumerate(frames):
        pan, tilt = HEAD_POSES[k // 2]
        assert np.allclose(f.T_base_camera, model.T_root_optical(pan, tilt))


def test_a_requested_label_picks_the_best_object_and_fails_when_absent(robot: MockRobot, ctx: SkillContext) -> None:
    run = run_skill(scan.spec, ctx, {"label": "blue", "size": [0.08, 0.08, 0.12]}, step=lambda: robot.spin(0.05))
    assert run.status is SkillStatus.SUCCESS, run.failure
    assert run.outputs["object"]["label"] == "blue"
    assert np.linalg.norm(np.array(run.outputs["object"]["position"]) - SCENE[2].centre) < 0.02
    assert [o["label"] for o in run.outputs["objects"]] == ["blue"]  # only the class asked for
    run = run_skill(scan.spec, ctx, {"label": "green"}, step=lambda: robot.spin(0.05))
    assert run.status is SkillStatus.FAILURE and run.failure.kind is FailureKind.EXECUTION
    assert "no 'green' seen in 8 predictions from 4 views" in run.failure.reason
    assert robot.head.targets[-1] == robot.head.home


def test_cancel_mid_scan_stops_and_sends_the_head_home(robot: MockRobot, ctx: SkillContext) -> None:
    run = SkillRun(scan.spec, ctx, {})
    run.start()
    for _ in range(12):
        robot.spin(0.05)
        run.tick()
    assert run.status is SkillStatus.RUNNING
    run.cancel()
    while run.status is SkillStatus.CANCELLING:
        robot.spin(0.05)
        run.tick()
    assert run.status is SkillStatus.CANCELLED
    assert robot.head.targets[-1] == robot.head.home and 1 < len(robot.head.targets) < 6


def test_a_head_that_fails_fails_the_scan(robot: MockRobot, ctx: SkillContext) -> None:
    robot.head.fail_moves = {2}
    run = run_skill(scan.spec, ctx, {}, step=lambda: robot.spin(0.05))
    assert run.status is SkillStatus.FAILURE and run.failure.kind is FailureKind.EXECUTION
    assert "head move 2" in run.failure.reason
    assert robot.head.targets[-1] == robot.head.home


def test_without_a_head_one_view_from_where_the_camera_is() -> None:
    r = MockRobot(capabilities={"base", "camera"}, profile={"scan": {"settle_time": 0.0}})
    ctx = SkillContext.for_robot(r)
    ctx.world[WORLD_OBJECT_DETECTOR] = ColourBoxes()
    run = run_skill(scan.spec, ctx, {}, step=lambda: r.spin(0.05))
    assert run.status is SkillStatus.SUCCESS, run.failure
    assert run.outputs["views"] == 1 and run.outputs["predictions"] == 2 and r.camera.calls == 2


def _pred(label: str, conf: float, xyz: tuple[float, float, float], k: int) -> Prediction:
    frame = CameraFrame(np.zeros((2, 2, 3), np.uint8), None, CameraIntrinsics.from_fov(2, 2, 1.0), float(k), np.eye(4))
    return Prediction(label, conf, np.array(xyz, float), frame, (k, 0, 1, 1), k)


def test_fuse_groups_by_class_and_distance() -> None:
    preds = [
        _pred("pen", 0.6, (1.00, 0.00, 0.5), 0),
        _pred("pen", 0.9, (1.04, 0.02, 0.5), 1),
        _pred("pen", 0.7, (1.50, 0.00, 0.5), 2),   # another pen 0.5 m away
        _pred("box", 0.8, (1.02, 0.01, 0.5), 3),   # a different class at the same place
        _pred("pen", 0.5, (0.98, -0.02, 0.5), 4),
    ]
    objs = fuse(preds, merge_distance=0.1)
    assert sorted((o.label, o.seen) for o in objs) == [("box", 1), ("pen", 1), ("pen", 3)]
    pen = next(o for o in objs if o.label == "pen" and o.seen == 3)
    assert pen.confidence == pytest.approx((0.6 + 0.9 + 0.5) / 3)
    assert np.allclose(pen.position, [(1.00 + 1.04 + 0.98) / 3, 0.0, 0.5])
    assert pen.box == (1, 0, 1, 1)                   # the most confident prediction's box
    assert pen.last_box == (4, 0, 1, 1)              # the latest one's
    assert pen.spread == pytest.approx(math.hypot(0.0333333, 0.02), abs=1e-4)
    # a tighter radius splits the near pens
    assert len(fuse(preds, merge_distance=0.03)) > len(objs)


def test_point_head_moves_and_refuses(robot: MockRobot, ctx: SkillContext) -> None:
    from mmexec.skills.perception.scan import point_head

    run = run_skill(point_head.spec, ctx, {"tilt": 0.35}, step=lambda: robot.spin(0.05))
    assert run.status is SkillStatus.SUCCESS, run.failure
    assert (run.outputs["pan"], run.outputs["tilt"]) == pytest.approx((0.0, 0.35))
    run = run_skill(point_head.spec, ctx, {"pan": 2.0}, step=lambda: robot.spin(0.05))
    assert run.status is SkillStatus.FAILURE and "pan = 2.0000 rad outside its limits" in run.failure.reason
    headless = SkillContext.for_robot(MockRobot(capabilities={"camera"}))
    run = run_skill(point_head.spec, headless, {}, step=lambda: None)
    assert run.status is SkillStatus.FAILURE and run.failure.kind is FailureKind.PRECONDITION


def test_a_mock_config_can_give_the_robot_a_head(tmp_path) -> None:
    from mmexec.executive.config import build_robot, load_config

    cfg = tmp_path / "mock.yaml"
    cfg.write_text("backend: mock\nmock:\n  capabilities: [base, camera, head]\n")
    loaded = load_config(cfg)
    assert loaded.capabilities() == {"base", "camera", "head"}
    robot = build_robot(loaded)
    assert robot.head is not None and robot.camera.head is robot.head
