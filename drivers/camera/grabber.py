"""A grabber thread that keeps a camera's latest frame, so ``frame()`` never blocks.

:class:`GrabbingCamera` owns the thread and the frame bookkeeping; subclasses open and
read the device (:meth:`_open_device`, :meth:`_grab`, :meth:`_close_device`). ``_grab``
may block for up to about a frame period (it runs on the grabber thread, never on a tick).

``frame()`` returns None before the first frame and whenever the newest frame is older
than ``frame_timeout`` [s, clock time]: the device stopped delivering. The dropout is
logged once and reported by :meth:`GrabbingCamera.health`.
"""

from __future__ import annotations

import abc
import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Self

import numpy as np

from mmexec.drivers.camera.errors import CameraError
from mmexec.drivers.interfaces import (
    Camera,
    CameraFrame,
    CameraIntrinsics,
    CapabilityError,
    Clock,
    MonotonicClock,
)

__all__ = ["CameraHealth", "GrabbingCamera"]

log = logging.getLogger(__name__)



@dataclass(frozen=True)
class CameraHealth:
    """What the grabber knows: ``frames`` delivered, ``age`` [s] of the newest (None
    before the first), ``dropout`` (no frame for longer than the timeout), last ``error``."""

    frames: int
    age: float | None
    dropout: bool
    error: str


class GrabbingCamera(Camera):
    """Camera capability fed by a grabber thread. Construction does no I/O: :meth:`open`.

    ``T_base_camera`` is the optical frame in the mount's parent: ``base_link`` by
    default, or the link given by ``link_pose`` (a callable returning ``T_base_link``
    4x4 at grab time, e.g. an arm's ``tool0`` for a wrist camera). ``base_pose`` returns
    ``T_map_base`` at grab time. Both are called on the grabber thread and must not block.
    """

    def __init__(self, name: str, intrinsics: CameraIntrinsics | None, T_base_camera: np.ndarray,
                 frame_timeout: float, clock: Clock | None = None,
                 base_pose: Callable[[], np.ndarray] | None = None,
                 link_pose: Callable[[], np.ndarray] | None = None) -> None:
        self.name = name
        self._intrinsics = intrinsics
        self._T_base_camera = np.array(T_base_camera, dtype=float)
        self.frame_timeout = frame_timeout
        self.clock: Clock = clock or MonotonicClock()
        self._base_pose = base_pose
        self._link_pose = link_pose
        self._lock = threading.Lock()
        self._latest: CameraFrame | None = None
        self._frames = 0
        self._error = ""
        self._dropout = False
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()

    # -- subclasses
    @abc.abstractmethod
    def _open_device(self) -> None:
        """Open the device; raise CameraError naming it on failure."""

    @abc.abstractmethod
    def _grab(self) -> tuple[np.ndarray, np.ndarray | None] | None:
        """Next (rgb HxWx3 uint8, depth HxW float32 m or None), or None if none came."""

    @abc.abstractmethod
    def _close_device(self) -> None:
        """Release the device (never raises)."""

    # -- lifecycle
    def open(self) -> None:
        """Open the device and start grabbing. Blocking: call at setup, not from a tick."""
        if self._thread is not None:
            return
        self._open_device()
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name=f"{self.name}-grab", daemon=True)
        self._thread.start()

    def close(self) -> None:
        """Stop grabbing and release the device."""
        t, self._thread = self._thread, None
        self._stop.set()
        if t is not None:
            t.join(timeout=2.0)
            if t.is_alive():
                log.warning("%s: grabber thread still blocked in a read after 2 s", self.name)
        self._close_device()

    def __enter__(self) -> Self:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- Camera
    @property
    def intrinsics(self) -> CameraIntrinsics:
        if self._intrinsics is None:
            raise CameraError(f"{self.name}: intrinsics not known yet: call open() first")
        return self._intrinsics

    def pose_in_base(self) -> np.ndarray:
        """``T_base_camera`` now: the configured mount, moved by the parent link's pose
        when the camera rides on one (a wrist camera)."""
        if self._link_pose is not None:
            return self._link_pose() @ self._T_base_camera
        return self._T_base_camera.copy()

    def frame(self) -> CameraFrame | None:
        """The newest frame, or None before the first one or during a dropout. Never blocks."""
        with self._lock:
            f = self._latest
            if f is None:
                return None
            age = self.clock.now() - f.stamp
            if age > self.frame_timeout:
                if not self._dropout:
                    log.warning("%s: no frame for %.2f s (timeout %.2f s): camera stopped "
                                "delivering", self.name, age, self.frame_timeout)
                    self._dropout = True
                return None
            if self._dropout:
                log.info("%s: frames again", self.name)
                self._dropout = False
            return f

    def health(self) -> CameraHealth:
        """Frames delivered, newest frame age, dropout and last error (for status displays)."""
        self.frame()  # refresh the dropout flag
        with self._lock:
            age = None if self._latest is None else self.clock.now() - self._latest.stamp
            return CameraHealth(self._frames, age, self._dropout, self._error)

    # -- thread
    def _run(self) -> None:
        misses = 0
        while not self._stop.is_set():
            try:
                got = self._grab()
            except CameraError as e:
                self._set_error(str(e))
                self._stop.wait(0.05)
                continue
            if got is None:
                misses += 1
                self._stop.wait(0.005 if misses < 3 else 0.05)  # never spin on a dead device
                continue
            misses = 0
            rgb, depth = got
            intr = self._intrinsics
            h, w = rgb.shape[:2]
            if intr is not None and (w, h) != (intr.width, intr.height):
                self._set_error(f"{self.name}: delivers {w}x{h} frames but the intrinsics are "
                                f"for {intr.width}x{intr.height}: fix width/height in the config")
                self._stop.wait(0.05)
                continue
            if intr is None:
                continue
            try:
                T_map_base = self._base_pose() if self._base_pose is not None else np.eye(4)
                T_base_camera = self.pose_in_base()
            except CapabilityError as e:  # the base or the carrying arm went away
                self._set_error(f"{self.name}: frame pose unknown: {e}")
                self._stop.wait(0.05)
                continue
            frame = CameraFrame(rgb, depth, intr, self.clock.now(), T_base_camera, T_map_base)
            with self._lock:
                self._latest = frame
                self._frames += 1
                self._error = ""

    def _set_error(self, message: str) -> None:
        with self._lock:
            if message != self._error:
                log.error("%s", message)
            self._error = message
