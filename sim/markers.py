"""ArUco marker textures generated at load time with cv2.aruco (DICT_4X4_50).

The texture is the marker (6 x 6 cells: border + 4 x 4 bits) plus a one-cell white
quiet zone, so a marker of side ``s`` [m] is printed on a square of side ``s * 8 / 6``.
"""

from __future__ import annotations

import logging
import os
import tempfile
from pathlib import Path

import cv2
import numpy as np

__all__ = ["MARKER_DICT", "QUIET_RATIO", "marker_image", "marker_texture_path"]

log = logging.getLogger(__name__)

MARKER_DICT = cv2.aruco.DICT_4X4_50
QUIET_RATIO = 8.0 / 6.0  # printed square side / black marker side
_CELL_PX = 32


def marker_image(marker_id: int, cell_px: int = _CELL_PX) -> np.ndarray:
    """Grayscale uint8 image of marker ``marker_id`` with a one-cell white border."""
    d = cv2.aruco.getPredefinedDictionary(MARKER_DICT)
    img = cv2.aruco.generateImageMarker(d, int(marker_id), 6 * cell_px)
    return cv2.copyMakeBorder(img, cell_px, cell_px, cell_px, cell_px, cv2.BORDER_CONSTANT, value=255)


def marker_texture_path(marker_id: int, cache_dir: Path | None = None) -> Path:
    """Write (once) and return the PNG texture of ``marker_id`` in ``cache_dir``
    (default: a per-user folder under the system temp dir)."""
    folder = cache_dir or Path(tempfile.gettempdir()) / f"mmexec-markers-{os.getuid()}"
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"aruco4x4_{marker_id:02d}_{_CELL_PX}.png"
    if not path.exists():
        tmp = path.with_suffix(f".{os.getpid()}.png")
        if not cv2.imwrite(str(tmp), cv2.cvtColor(marker_image(marker_id), cv2.COLOR_GRAY2BGR)):
            raise OSError(f"cannot write marker texture {tmp}")
        os.replace(tmp, path)
        log.debug("wrote marker texture %s", path)
    return path
