"""Chase-camera video of a simulation run (``--record FILE.mp4|.gif``)."""

from __future__ import annotations

import logging
import math
from pathlib import Path
from typing import Any

import numpy as np
import pybullet as p

__all__ = ["Recorder"]

log = logging.getLogger(__name__)


class Recorder:
    """Samples a low-resolution chase view every ``period`` sim seconds and streams it to
    ``path`` (.mp4 through imageio-ffmpeg, .gif through imageio). :meth:`close` finalises
    the file. The camera sits ``distance`` [m] behind and ``height`` [m] above the base,
    looking at a point 0.5 m ahead of it."""

    def __init__(self, path: Path, cid: int, *, period: float = 0.5, size: tuple[int, int] = (320, 240),
                 distance: float = 1.8, height: float = 1.4) -> None:
        suffix = path.suffix.lower()
        if suffix not in (".mp4", ".gif"):
            raise ValueError(f"--record {path}: the file must end in .mp4 or .gif")
        self.path, self._cid, self.period, self.size = path, cid, period, size
        self._dist, self._height = distance, height
        self._writer: Any = None
        self._next = 0.0
        self.frames = 0
        self._proj = p.computeProjectionMatrixFOV(60.0, size[0] / size[1], 0.05, 20.0, physicsClientId=cid)

    def _open(self) -> Any:
        import imageio.v2 as imageio

        self.path.parent.mkdir(parents=True, exist_ok=True)
        fps = max(1, round(1.0 / self.period))
        if self.path.suffix.lower() == ".mp4":
            return imageio.get_writer(str(self.path), fps=fps, codec="libx264", macro_block_size=8,
                                      ffmpeg_log_level="error")
        return imageio.get_writer(str(self.path), mode="I", duration=1000.0 * self.period, loop=0)

    def sample(self, now: float, base_xy: tuple[float, float], yaw: float) -> None:
        """Render a chase frame when ``now`` [s] has reached the next sample time."""
        if now + 1e-9 < self._next:
            return
        self._next = now + self.period
        x, y = base_xy
        eye = [x - self._dist * math.cos(yaw), y - self._dist * math.sin(yaw), self._height]
        target = [x + 0.5 * math.cos(yaw), y + 0.5 * math.sin(yaw), 0.3]
        view = p.computeViewMatrix(eye, target, [0, 0, 1], physicsClientId=self._cid)
        w, h = self.size
        _, _, rgba, _, _ = p.getCameraImage(w, h, view, self._proj, renderer=p.ER_TINY_RENDERER, shadow=0,
                                            flags=p.ER_NO_SEGMENTATION_MASK, physicsClientId=self._cid)
        if self._writer is None:
            self._writer = self._open()
        self._writer.append_data(np.asarray(rgba, dtype=np.uint8).reshape(h, w, 4)[:, :, :3])
        self.frames += 1

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()
            self._writer = None
            log.info("recorded %d frames to %s", self.frames, self.path)
