"""Perception algorithms: ArUco marker detection and pose (:mod:`.markers`), multi-frame
pose averaging (:mod:`.averaging`) and synthetic marker views for tests and benchmarks
(:mod:`.synthetic`). Plain Python over :class:`mmexec.drivers.interfaces.CameraFrame`."""

from __future__ import annotations

from mmexec.skills.perception.averaging import MarkerPoseEstimator, PoseEstimate, average_poses
from mmexec.skills.perception.markers import (
    DetectorConfig,
    MarkerDetection,
    MarkerDetector,
    MarkerObservation,
    estimate_marker_pose,
    observe_markers,
    refine_pose_with_depth,
)

__all__ = [
    "DetectorConfig",
    "MarkerDetection",
    "MarkerDetector",
    "MarkerObservation",
    "MarkerPoseEstimator",
    "PoseEstimate",
    "average_poses",
    "estimate_marker_pose",
    "observe_markers",
    "refine_pose_with_depth",
]
