"""Helpers for the fetch mission's skill tests on the mock backend: a small occupancy map,
a robot profile (nav, arm, camera, search and fetch sections), and a camera that renders
synthetic ArUco frames of markers placed in the map
(``mmexec.skills.perception.synthetic``), seen from the mock base's pose."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from mmexec.drivers.interfaces import Camera, CameraFrame, CameraIntrinsics, OccupancyGrid, Pose2D
from mmexec.drivers.mock.robot import MockRobot
from mmexec.skills.base import SkillContext
from mmexec.skills.perception.synthetic import render_markers_view

MARKER_LENGTH = 0.10  # m: big markers keep the synthetic frames small and fast

#: Camera on the base: 0.5 m up, optical z along base +x (as the MockCamera).
T_BASE_CAMERA = np.array([[0.0, 0.0, 1.0, 0.0], [-1.0, 0.0, 0.0, 0.0], [0.0, -1.0, 0.0, 0.5], [0.0, 0.0, 0.0, 1.0]])


def marker_pose(x: float, y: float, z: float, normal_yaw: float) -> np.ndarray:
    """``T_map_marker`` of an upright marker at (x, y, z) [m] whose face (marker z) points
    along ``normal_yaw`` [rad] in map; marker y is up, x = y cross z."""
    zc = np.array([math.cos(normal_yaw), math.sin(normal_yaw), 0.0])
    yc = np.array([0.0, 0.0, 1.0])
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = np.cross(yc, zc), yc, zc, (x, y, z)
    return T


class MarkerCamera(Camera):
    """RGB-D frames of ``markers`` ({id: T_map_marker}) rendered from the base's true pose.

    A marker is drawn when it is in front of the camera, within ``max_range`` [m], facing
    it and with its centre inside the image. ``headings`` records the base heading [rad]
    at every frame() call (the views a search checks)."""

    def __init__(self, robot: MockRobot, markers: dict[int, np.ndarray], *, width: int = 320, height: int = 240,
                 hfov: float = 0.5, max_range: float = 4.0) -> None:
        self._robot = robot
        self.markers = markers
        self._intr = CameraIntrinsics.from_fov(width, height, hfov)
        self.max_range = max_range
        self.headings: list[float] = []
        self.enabled = True

    @property
    def intrinsics(self) -> CameraIntrinsics:
        return self._intr

    def pose_in_base(self) -> np.ndarray:
        return T_BASE_CAMERA.copy()

    def visible(self, T_map_base: np.ndarray) -> list[tuple[np.ndarray, int]]:
        T_cam_map = np.linalg.inv(T_map_base @ T_BASE_CAMERA)
        K = self._intr.matrix()
        out = []
        for mid, T in self.markers.items():
            Tc = T_cam_map @ T
            p = Tc[:3, 3]
            if p[2] <= 0.05 or np.linalg.norm(p) > self.max_range or float(np.dot(Tc[:3, 2], p)) >= 0:
                continue
            u, v = (K @ p)[:2] / p[2]
            if 0 <= u < self._intr.width and 0 <= v < self._intr.height:
                out.append((Tc, mid))
        return out

    def frame(self) -> CameraFrame | None:
        base = self._robot.base
        assert base is not None
        pose = base.state().pose
        self.headings.append(pose.theta)
        if not self.enabled:
            return None
        T_map_base = pose.matrix()
        seen = self.visible(T_map_base)
        if seen:
            view = render_markers_view(self._intr, seen, MARKER_LENGTH, texture=False, supersample=2)
            rgb, depth = view.rgb, view.depth
        else:
            rgb = np.full((self._intr.height, self._intr.width, 3), 150, np.uint8)
            depth = np.full((self._intr.height, self._intr.width), 3.0, np.float32)
        return CameraFrame(rgb, depth, self._intr, self._robot.clock.now(), T_BASE_CAMERA.copy(), T_map_base)


def room_grid(size: tuple[float, float] = (6.0, 6.0), resolution: float = 0.05,
              boxes: list[tuple[float, float, float, float]] = ()) -> OccupancyGrid:
    """A walled room [0, sx] x [0, sy] with occupied rectangles (x0, y0, x1, y1) [m]."""
    w, h = round(size[0] / resolution), round(size[1] / resolution)
    data = np.zeros((h, w), np.int8)
    data[0, :] = data[-1, :] = data[:, 0] = data[:, -1] = 100
    for x0, y0, x1, y1 in boxes:
        data[int(y0 / resolution):math.ceil(y1 / resolution), int(x0 / resolution):math.ceil(x1 / resolution)] = 100
    return OccupancyGrid(data, resolution, Pose2D(0.0, 0.0, 0.0))


FETCH_PROFILE: dict[str, Any] = {
    "home": [1.0, 1.0, 0.0],
    "named_poses": {
        "home": [0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        "sleep": [0.0, -1.1, 1.55, 0.0, 0.5, 0.0],
        "tuck": [0.0, -0.4, 1.1, 0.0, 1.4, 0.0],
        "carry": [0.0, -0.2, 0.6, 0.0, 0.5, 0.0],
    },
    "nav": {"max_v": 0.6, "max_w": 2.0, "accel_v": 1.0, "accel_w": 3.5, "timeout": 60.0,
            "approach_distances": [0.5, 0.7, 0.9]},
    "arm": {"model": "locobot_wx250s", "time_limit": 1.0, "attempts": 3, "stow": "tuck", "carry": "carry",
            "grasp_force": 5.0, "min_held_width": 0.02},
    "camera": {"marker_length": MARKER_LENGTH, "detect_frames": 2},
    "search": {"locations": [[4.0, 1.0, 0.0], [4.0, 4.0, 3.14159]], "step_deg": 30, "settle_time": 0.1},
    "fetch": {
        "depot": {"base": [1.0, 4.0, 1.5708], "place": [1.0, 4.45, 0.25]},
        "back_off": 0.1,
    },
}


def run_skill(ctx: SkillContext, name: str, params: dict[str, Any] | None = None, *, period: float = 0.05,
              max_ticks: int = 20_000, on_tick: Any = None) -> Any:
    """Run the registered skill ``name`` to completion on ``ctx``'s mock robot; returns the SkillRun."""
    import mmexec.skills.fetch  # noqa: F401  (registers the fetch mission's skills)
    from mmexec.skills.base import REGISTRY, SkillRun, SkillStatus

    run = SkillRun(REGISTRY.get(name), ctx, params or {})
    run.start()
    ticks = 0
    while run.status is SkillStatus.RUNNING:
        ctx.robot.spin(period)
        run.tick()
        wait_for_planner(ctx)
        if on_tick is not None:
            on_tick()
        ticks += 1
        assert ticks < max_ticks, f"{name} still running after {ticks} ticks"
    return run


def wait_for_planner(ctx: SkillContext) -> None:
    """Block until the arm workspace's planning thread has finished the jobs handed to it
    so far (a no-op queued behind them on its single worker), so a test ticks the skill
    deterministically instead of racing the planner with thousands of empty ticks."""
    from mmexec.skills.manipulation.arm import WORLD_ARM

    ws = ctx.world.get(WORLD_ARM)
    executor = getattr(ws, "executor", None)
    if executor is not None:
        executor.submit(lambda: None).result(timeout=60.0)


def events_of(ctx: SkillContext, event: str) -> list[dict[str, Any]]:
    return [f for e, f in ctx.events if e == event]  # type: ignore[attr-defined]
