"""Cameras: RGB over OpenCV VideoCapture (UVC) and RGB-D from an Intel RealSense (optional).

* :mod:`.config`: :class:`CameraConfig` (device, mode, intrinsics or FOV, mount pose),
  loaded through the project's safe YAML loader;
* :mod:`.grabber`: :class:`GrabbingCamera`, the grabber thread that keeps the latest frame
  so that :meth:`~mmexec.drivers.interfaces.Camera.frame` never blocks;
* :mod:`.uvc`: :class:`UVCCamera`; :mod:`.realsense`: :class:`RealSenseCamera` (needs
  ``pip install mmexec[realsense]``, imported lazily).
"""
