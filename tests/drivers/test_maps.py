"""``mmexec.drivers.maps``: a map image that is no regular file, or too large, is refused
at once with one located line (it was read whole with ``read_bytes``: ``image:
/dev/zero`` filled memory, a FIFO hung the robot backend's start)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from mmexec.config.yamlload import InputError
from mmexec.drivers.maps import MAX_IMAGE_BYTES, load_map


def _yaml(tmp_path: Path, image: str) -> Path:
    p = tmp_path / "room.yaml"
    p.write_text(f"image: {image}\nresolution: 0.05\norigin: [0.0, 0.0, 0.0]\n")
    return p


def test_a_device_as_the_map_image_is_refused(tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r"/dev/zero:1:1: .*(not a regular file|device)"):
        load_map(_yaml(tmp_path, "/dev/zero"))


def test_a_fifo_as_the_map_image_is_refused_without_waiting(tmp_path: Path) -> None:
    os.mkfifo(tmp_path / "m.pgm")
    with pytest.raises(InputError, match=r"m\.pgm:1:1: .*(FIFO|not a regular file)"):
        load_map(_yaml(tmp_path, "m.pgm"))


def test_an_image_over_the_cap_is_refused_from_its_size(tmp_path: Path) -> None:
    with (tmp_path / "m.pgm").open("wb") as f:  # sparse: no blocks on disk
        f.truncate(MAX_IMAGE_BYTES + 1)
    with pytest.raises(InputError, match=r"m\.pgm:1:1: .*(larger|too large|bytes)"):
        load_map(_yaml(tmp_path, "m.pgm"))
