"""Robot models for the pybullet backend (URDF with primitive geometry) and their metadata.

The models are the robot descriptions' (:mod:`mmexec.drivers.descriptions`): their link
trees are written to the ``*.urdf`` files of this package by
:mod:`mmexec.sim.models.urdfgen`. Use :func:`urdf_path` to load a model
(``p.loadURDF(str(urdf_path("ur5e_robotiq")))``) and :data:`MODEL_INFO` for the frame and
joint names a simulator needs (each description's ``info``).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from types import MappingProxyType

from mmexec.drivers.descriptions import DESCRIPTIONS, ModelInfo, get

__all__ = ["MODEL_INFO", "ModelInfo", "urdf_path"]

#: The model info of every registered robot description, by name.
MODEL_INFO: Mapping[str, ModelInfo] = MappingProxyType({name: d.info for name, d in DESCRIPTIONS.items()})


def urdf_path(name: str) -> Path:
    """Absolute path of the URDF of model ``name`` (a key of :data:`MODEL_INFO`); KeyError
    listing the known models."""
    return get(name).urdf_path
