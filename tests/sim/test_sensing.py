"""Camera depth and marker pose, lidar ranges: against the world's known geometry."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from mmexec.drivers.interfaces import Pose2D
from mmexec.sim.backend import build


@pytest.fixture(scope="module")
def robot(sim_section, bench_world):
    sec = sim_section(f"robot: locobot_wx250s\nworld: {bench_world}\nlidar: {{noise: 0.0, beams: 360}}\n"
                      "odometry_noise: {linear: 0.0, angular: 0.0}\n")
    r = build(sec, profile={}, seed=0, options={})
    r.spin(0.5)  # let items settle
    yield r
    r.close()


def test_intrinsics_from_the_d435_stand_in(robot):
    K = robot.camera.intrinsics
    assert (K.width, K.height) == (640, 480)
    assert K.fx == pytest.approx(320 / math.tan(0.994837 / 2))


def test_box_face_renders_at_its_metric_depth(robot):
    robot.core.place_base(Pose2D(1.0, 1.0, 0.0))
    f = robot.camera.frame()
    assert f is not None and f.depth is not None and f.depth.dtype == np.float32
    cam_x = (robot.core.base_T() @ f.T_base_camera)[0, 3]
    face_x = robot.truth.item_pose("big")[0, 3] - 0.07
    K = f.intrinsics
    # centre pixel row of the camera (optical axis is horizontal, tilt 0) hits the box face
    d = float(f.depth[round(K.cy), round(K.cx)])
    assert abs(d - (face_x - cam_x)) < 0.01
    assert abs(face_x - cam_x - 1.0) < 0.05  # the world puts it about 1 m away


def test_marker_pose_at_one_metre(robot):
    robot.core.place_base(Pose2D(1.0, 1.0, 0.0))
    f = robot.camera.frame()
    gray = cv2.cvtColor(f.rgb, cv2.COLOR_RGB2GRAY)
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    det = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50), params)
    corners, ids, _ = det.detectMarkers(gray)
    assert ids is not None and list(np.ravel(ids)) == [7]
    s = 0.1
    obj = np.array([[-s / 2, s / 2, 0], [s / 2, s / 2, 0], [s / 2, -s / 2, 0], [-s / 2, -s / 2, 0]])
    ok, rvec, tvec = cv2.solvePnP(obj, corners[0].reshape(4, 2), f.intrinsics.matrix(), None,
                                  flags=cv2.SOLVEPNP_IPPE_SQUARE)
    assert ok
    T_cam_marker = np.eye(4)
    T_cam_marker[:3, :3] = cv2.Rodrigues(rvec)[0]
    T_cam_marker[:3, 3] = tvec.ravel()
    # truth: marker frame = item +x face centre, axes (right, up, out) = item (y, z, x)
    Ti = robot.truth.item_pose("big")
    T_map_marker = np.eye(4)
    T_map_marker[:3, :3] = Ti[:3, [1, 2, 0]]
    T_map_marker[:3, 3] = Ti[:3, 3] + 0.0705 * Ti[:3, 0]
    truth = np.linalg.inv(robot.core.base_T() @ f.T_base_camera) @ T_map_marker
    assert 0.9 < np.linalg.norm(truth[:3, 3]) < 1.1
    assert np.linalg.norm(T_cam_marker[:3, 3] - truth[:3, 3]) < 0.01
    dR = T_cam_marker[:3, :3].T @ truth[:3, :3]
    angle = math.degrees(math.acos(max(-1.0, min(1.0, (np.trace(dR) - 1) / 2))))
    assert angle < 2.0


def _expected_ranges(lidar_T: np.ndarray, angles: np.ndarray, room=(4.0, 3.0)) -> np.ndarray:
    o = lidar_T[:3, 3]
    out = []
    for a in angles:
        d = lidar_T[:3, :3] @ np.array([math.cos(a), math.sin(a), 0.0])
        ts = []
        for axis, lim in ((0, 0.0), (0, room[0]), (1, 0.0), (1, room[1])):
            if abs(d[axis]) > 1e-12:
                t = (lim - o[axis]) / d[axis]
                if t > 0:
                    ts.append(t)
        out.append(min(ts))
    return np.array(out)


def test_lidar_ranges_match_walls(robot):
    robot.core.place_base(Pose2D(0.8, 1.6, 0.3))
    scan = robot.lidar.scan()
    assert scan is not None and len(scan.ranges) == 360
    assert scan.angle_increment == pytest.approx(2 * math.pi / 360)
    T = robot.core.base_T() @ scan.T_base_lidar
    assert T[2, 3] == pytest.approx(0.63693, abs=1e-4)  # laser_frame_link height
    exp = _expected_ranges(T, scan.angles)
    # beams above the walls' obstacles: only walls are at the lidar's 0.637 m height
    # except the 0.9 m tall block; compare the beams that the block does not shadow
    err = np.abs(scan.ranges - exp)
    block_dir = np.arctan2(2.4 - T[1, 3], 3.5 - T[0, 3])
    yaw = math.atan2(T[1, 0], T[0, 0])
    beam_dir = np.array([(yaw + a + math.pi) % (2 * math.pi) - math.pi for a in scan.angles])
    clear = np.abs(((beam_dir - block_dir) + math.pi) % (2 * math.pi) - math.pi) > 0.2
    assert clear.sum() > 300
    assert float(err[clear].max()) < 0.01
    assert np.all(scan.ranges[~clear] <= exp[~clear] + 0.01)  # the block is in front of the wall
