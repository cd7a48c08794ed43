"""Helpers for the button presser's skill tests on the mock backend: a robot profile, a
mock control panel that switches a button's latching light when the arm's pressing tip
(forward kinematics of the mock arm's joints) goes past 70 % of its travel inside the cap,
and a base-mounted camera that renders the panel's markers (``render_markers_view``) and
its lights (green disks when lit, dark when not) from the mock base's pose."""

from __future__ import annotations

import math
from typing import Any

import cv2
import numpy as np

from mmexec.drivers.interfaces import Camera, CameraFrame, CameraIntrinsics, OccupancyGrid, Pose2D
from mmexec.drivers.mock.robot import MockRobot
from mmexec.skills.base import REGISTRY, SkillContext, SkillRun, SkillStatus
from mmexec.skills.buttons.profile import ButtonsSettings
from mmexec.skills.manipulation import ArmKinematics

MARKER_LENGTH = 0.045
#: Camera on the base: 0.5 m up, optical z along base +x (as the MockCamera).
T_BASE_CAMERA = np.array([[0.0, 0.0, 1.0, 0.0], [-1.0, 0.0, 0.0, 0.0], [0.0, -1.0, 0.0, 0.5], [0.0, 0.0, 0.0, 1.0]])

PROFILE: dict[str, Any] = {
    "home": [1.0, 1.0, 0.0],
    "named_poses": {"home": [0.0] * 6, "tuck": [0.0, -0.4, 1.1, 0.0, 1.4, 0.0]},
    "nav": {"max_v": 0.6, "max_w": 2.0, "accel_v": 1.0, "accel_w": 3.5, "timeout": 60.0},
    "arm": {"model": "locobot_wx250s", "time_limit": 1.0, "attempts": 3, "stow": "tuck", "grasp_force": 5.0},
    "camera": {"marker_length": MARKER_LENGTH, "detect_frames": 1},
    "search": {"locations": [], "settle_time": 0.1},
    # the camera is on the base (no arm.look): the base turns, the arm does not sweep; the
    # pressing tip is the WX250s fingers' end, 17.5 mm beyond its tool point along x
    "buttons": {"tool_offset": [0.0175, 0.0, 0.0], "standoff": 0.6, "turn_deg": 120.0, "locator_position": [0.0, -0.25]},
}


def panel_pose(x: float, y: float, z: float, yaw: float) -> np.ndarray:
    """``T_map_panel`` of an upright face at (x, y, z) looking along ``yaw``."""
    c, s = math.cos(yaw), math.sin(yaw)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = (-s, c, 0.0), (0.0, 0.0, 1.0), (c, s, 0.0), (x, y, z)
    return T


def offset(T: np.ndarray, x: float, y: float, z: float = 0.0) -> np.ndarray:
    out = T.copy()
    out[:3, 3] = T[:3, :3] @ (x, y, z) + T[:3, 3]
    return out


class MockPanel:
    """The panel of ``settings`` at ``T_map_panel``: lights latch when the pressing tip
    goes past 70 % of a button's travel inside its cap (``dead``: buttons that never
    switch). :meth:`step` after each spin; ``depth`` the deepest tip travel per button [m]."""

    def __init__(self, robot: MockRobot, settings: ButtonsSettings, T_map_panel: np.ndarray,
                 dead: tuple[str, ...] = ()) -> None:
        assert robot.description is not None and robot.description.arm is not None
        self.robot = robot
        self.settings = settings
        self.T = T_map_panel
        tip = np.eye(4)
        tip[:3, 3] = settings.tool_offset
        self.kin = ArmKinematics.from_description(robot.description).with_tool_offset(tip)
        self.lit: set[str] = set()
        self.dead = set(dead)
        self.depth = {b.name: 0.0 for b in settings.buttons}

    def tip_in_panel(self) -> np.ndarray:
        assert self.robot.arm is not None and self.robot.base is not None
        T_map_tool = self.robot.base.pose.matrix() @ np.asarray(self.robot.arm.mount) @ self.kin.fk(
            self.robot.arm.state().positions)
        return (np.linalg.inv(self.T) @ T_map_tool[:, 3])[:3]

    def step(self) -> None:
        p = self.tip_in_panel()
        for b in self.settings.buttons:
            bx, by, bz = b.position
            if math.hypot(p[0] - bx, p[1] - by) <= b.diameter / 2:
                d = bz - p[2]
                self.depth[b.name] = max(self.depth[b.name], d)
                if d >= 0.7 * b.travel and b.name not in self.dead:
                    self.lit.add(b.name)


class PanelCamera(Camera):
    """RGB-D frames from the base camera: the panel's markers (``markers``: id ->
    T_map_marker, all of ``MARKER_LENGTH``) and its lights (``panel``) drawn in."""

    def __init__(self, robot: MockRobot, markers: dict[int, np.ndarray], panel: MockPanel | None = None,
                 *, width: int = 480, height: int = 360, hfov: float = 1.2) -> None:
        self._robot = robot
        self.markers = markers
        self.panel = panel
        self._intr = CameraIntrinsics.from_fov(width, height, hfov)
        self.headings: list[float] = []

    @property
    def intrinsics(self) -> CameraIntrinsics:
        return self._intr

    def pose_in_base(self) -> np.ndarray:
        return T_BASE_CAMERA.copy()

    def frame(self) -> CameraFrame | None:
        from mmexec.skills.perception.synthetic import render_markers_view

        base = self._robot.base
        assert base is not None
        pose = base.state().pose
        self.headings.append(pose.theta)
        T_map_base = pose.matrix()
        T_cam_map = np.linalg.inv(T_map_base @ T_BASE_CAMERA)
        seen = []
        for mid, T in self.markers.items():
            Tc = T_cam_map @ T
            if Tc[2, 3] > 0.05 and float(np.dot(Tc[:3, 2], Tc[:3, 3])) < 0:
                seen.append((Tc, mid))
        h, w = self._intr.height, self._intr.width
        if seen:
            view = render_markers_view(self._intr, seen, MARKER_LENGTH, texture=False, supersample=2)
            rgb, depth = view.rgb.copy(), view.depth
        else:
            rgb = np.full((h, w, 3), 150, np.uint8)
            depth = np.full((h, w), 3.0, np.float32)
        if self.panel is not None:
            K = self._intr.matrix()
            for b in self.panel.settings.buttons:
                pc = T_cam_map @ self.panel.T @ np.array([b.light[0], b.light[1], 0.0, 1.0])
                if pc[2] <= 0.05:
                    continue
                u, v = (K @ pc[:3])[:2] / pc[2]
                r = self._intr.fx * b.light_diameter / 2 / pc[2]
                colour = (60, 250, 60) if b.name in self.panel.lit else (30, 30, 30)
                cv2.circle(rgb, (round(u), round(v)), max(1, round(r)), colour, -1)
        return CameraFrame(rgb, depth, self._intr, self._robot.clock.now(), T_BASE_CAMERA.copy(), T_map_base)


def room_grid(size: tuple[float, float] = (6.0, 6.0), resolution: float = 0.05) -> OccupancyGrid:
    """A walled, empty room [0, sx] x [0, sy]."""
    w, h = round(size[0] / resolution), round(size[1] / resolution)
    data = np.zeros((h, w), np.int8)
    data[0, :] = data[-1, :] = data[:, 0] = data[:, -1] = 100
    return OccupancyGrid(data, resolution, Pose2D(0.0, 0.0, 0.0))


def run_skill(ctx: SkillContext, name: str, params: dict[str, Any] | None = None, *, period: float = 0.05,
              max_ticks: int = 20_000, panel: MockPanel | None = None) -> SkillRun:
    """Run the registered skill ``name`` to completion on ``ctx``'s mock robot (stepping
    ``panel`` after each spin); returns the SkillRun."""
    import mmexec.skills.buttons  # noqa: F401  (registers the skills)
    from mmexec.skills.manipulation.arm import WORLD_ARM

    run = SkillRun(REGISTRY.get(name), ctx, params or {})
    run.start()
    ticks = 0
    while run.status is SkillStatus.RUNNING:
        ctx.robot.spin(period)
        if panel is not None:
            panel.step()
        run.tick()
        ws = ctx.world.get(WORLD_ARM)
        if getattr(ws, "executor", None) is not None:
            ws.executor.submit(lambda: None).result(timeout=60.0)  # the planner has finished what it was given
        ticks += 1
        assert ticks < max_ticks, f"{name} still running after {ticks} ticks"
    return run


def events_of(ctx: SkillContext, event: str) -> list[dict[str, Any]]:
    return [f for e, f in ctx.events if e == event]  # type: ignore[attr-defined]
