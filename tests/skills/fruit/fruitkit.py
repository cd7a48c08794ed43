"""Helpers for the fruit skill tests on the mock backend: a camera that renders coloured
spheres (fruit) placed in ``map`` exactly (ray/sphere depth, flat-shaded colour), a UR5e
mock robot with the fruit profile, and a skill runner."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from mmexec.drivers.descriptions import get
from mmexec.drivers.interfaces import Camera, CameraFrame, CameraIntrinsics, Pose2D
from mmexec.drivers.mock.robot import MockArm, MockGripper, MockRobot
from mmexec.skills.perception.sphere import render_sphere_depth

#: Camera on the base: 0.8 m up, 0.3 m ahead, optical z along base +x.
T_BASE_CAMERA = np.array([[0.0, 0.0, 1.0, 0.3], [-1.0, 0.0, 0.0, 0.0], [0.0, -1.0, 0.0, 0.8], [0.0, 0.0, 0.0, 1.0]])

RGB = {"apple": (205, 18, 13), "yellow_ball": (235, 204, 20), "green_ball": (30, 166, 38), "blue_ball": (20, 56, 217)}


class SphereCamera(Camera):
    """RGB-D frames of ``spheres`` [(label, centre in map, radius)] seen from the mock
    base's pose: each pixel takes the nearest sphere's colour (shaded by the cosine of
    its normal with the ray, so the rim is darker) and depth; the background is grey at
    ``background`` m. ``holes``: fraction of the sphere pixels given no depth (seeded)."""

    def __init__(self, robot: MockRobot, spheres: list[tuple[str, np.ndarray, float]], *, width: int = 320,
                 height: int = 240, hfov: float = 1.2, background: float = 3.0, holes: float = 0.0) -> None:
        self._robot = robot
        self.spheres = spheres
        self._intr = CameraIntrinsics.from_fov(width, height, hfov)
        self.background = background
        self.holes = holes
        self._rng = np.random.default_rng(0)

    @property
    def intrinsics(self) -> CameraIntrinsics:
        return self._intr

    def pose_in_base(self) -> np.ndarray:
        return T_BASE_CAMERA.copy()

    def frame(self) -> CameraFrame | None:
        base = self._robot.base
        assert base is not None
        T_map_base = base.state().pose.matrix()
        T_cam_map = np.linalg.inv(T_map_base @ T_BASE_CAMERA)
        h, w = self._intr.height, self._intr.width
        depth = np.full((h, w), self.background, np.float32)
        rgb = np.full((h, w, 3), 128, np.uint8)
        x = (np.arange(w) - self._intr.cx) / self._intr.fx
        y = (np.arange(h) - self._intr.cy) / self._intr.fy
        X, Y = np.meshgrid(x, y)
        for label, c_map, r in self.spheres:
            c = (T_cam_map @ np.append(c_map, 1.0))[:3]
            if c[2] <= r:
                continue
            d = render_sphere_depth(self._intr, c, r)
            hit = np.isfinite(d) & (d < depth)
            pts = np.stack([X * d, Y * d, d], axis=-1)
            n = (pts - c) / r
            ray = -np.stack([X, Y, np.ones_like(X)], axis=-1)
            ray /= np.linalg.norm(ray, axis=-1, keepdims=True)
            shade = np.clip(np.sum(n * ray, axis=-1), 0.3, 1.0)
            col = np.array(RGB[label], dtype=float)
            rgb[hit] = (col * shade[hit][:, None]).astype(np.uint8)
            depth[hit] = d[hit]
            if self.holes:
                idx = np.flatnonzero(hit)
                drop = self._rng.choice(idx, int(self.holes * len(idx)), replace=False)
                depth.reshape(-1)[drop] = np.nan
        return CameraFrame(rgb, depth, self._intr, self._robot.clock.now(), T_BASE_CAMERA.copy(), T_map_base)


#: A UR5e profile with the fruit section (look poses are the arm's current pose: the mock's camera is on the base).
FRUIT_PROFILE: dict[str, Any] = {
    "home": [0.0, 0.0, 0.0],
    "named_poses": {
        "tuck": [0.0, -1.9, 2.3, -1.97, -1.5708, 0.0],
        "look": [0.0, -1.9, 2.3, -1.97, -1.5708, 0.0],
        "drop": [2.718, -2.046, 1.959, -1.484, -1.5708, 0.0],
    },
    "arm": {"model": "ur5e_robotiq", "tcp_offset": 0.155, "stow": "tuck", "carry": "tuck", "look": "look",
            "grasp_force": 40.0, "min_held_width": 0.035, "time_limit": 2.0},
    "fruit": {"station": [0.0, 0.0, 0.0], "look_poses": ["look"], "settle": 0.0, "frames": 1,
              "robot_basket": {"box": [-0.205, 0.0, 0.46, 0.20, 0.46, 0.12], "drop_poses": ["drop"]}},
}


class MountedArm(MockArm):
    """The mock arm on the UR platform's mount (0.12, 0, 0.33) m in the base frame."""

    @property
    def mount(self) -> np.ndarray:
        T = np.eye(4)
        T[:3, 3] = get("ur5e_robotiq").arm_mount
        return T


def ur5e_robot(spheres: list[tuple[str, np.ndarray, float]], *, grasps: list[bool] | None = None) -> MockRobot:
    """A mock UR5e platform at the origin facing +x with a :class:`SphereCamera` of ``spheres``."""
    import copy

    desc = get("ur5e_robotiq")
    robot = MockRobot(profile=copy.deepcopy(FRUIT_PROFILE), description=desc)
    assert robot.base is not None
    robot.base.pose = Pose2D(0.0, 0.0, 0.0)
    assert desc.arm is not None
    robot.arm = MountedArm(robot.clock, limits=desc.arm.limits, start=FRUIT_PROFILE["named_poses"]["tuck"])
    robot.gripper = MockGripper(robot.clock, grasps=grasps if grasps is not None else [True], object_width=0.07)
    robot.camera = SphereCamera(robot, spheres)
    return robot


def fruit_at(x: float, y: float, z: float) -> np.ndarray:
    return np.array([x, y, z], dtype=float)


def run_skill(ctx: Any, name: str, params: dict[str, Any] | None = None, *, period: float = 0.05,
              max_ticks: int = 20_000) -> Any:
    """Run the registered skill ``name`` to completion on ``ctx``'s mock robot; returns the SkillRun."""
    import mmexec.skills.fruit  # noqa: F401  (registers the fruit skills)
    from mmexec.skills.base import REGISTRY, SkillRun, SkillStatus

    run = SkillRun(REGISTRY.get(name), ctx, params or {})
    run.start()
    ticks = 0
    while run.status is SkillStatus.RUNNING:
        ctx.robot.spin(period)
        run.tick()
        ticks += 1
        assert ticks < max_ticks, f"{name} still running after {ticks} ticks"
    return run


def events_of(ctx: Any, name: str) -> list[dict[str, Any]]:
    return [f for e, f in ctx.events if e == name]


__all__ = ["FRUIT_PROFILE", "RGB", "T_BASE_CAMERA", "SphereCamera", "events_of", "fruit_at", "math", "run_skill",
           "ur5e_robot"]
