"""Localisation against a map: AMCL (Probabilistic Robotics ch. 8, as ROS ``amcl``) and its
laser-reflector enhancement (``reflector-amcl-tracking-grasp`` section 3.1).

* :mod:`.motion`: the differential-drive odometry motion model;
* :mod:`.likelihood`: the likelihood-field range-finder model;
* :mod:`.reflectors`: reflector extraction, triangle matching, trilateration, weights;
* :mod:`.amcl`: the particle filter that combines them;
* :mod:`.landmarks`: a map's reflector posts, read from its map_server YAML;
* :mod:`.localizer`: the filter in the capability layer (the run config's
  ``localization:``): a robot whose base and camera report the localised pose;
* :mod:`.skill`: the ``localize`` skill (global localisation, turning in place).

The filter modules are pure numpy (+ OpenCV's distance transform), no capability I/O;
the localiser reads the robot's lidar and base.
"""

from mmexec.skills.localization.amcl import AmclConfig, Estimate, ParticleFilter
from mmexec.skills.localization.landmarks import ReflectorMap, load_reflectors
from mmexec.skills.localization.likelihood import BeamModel, LikelihoodField
from mmexec.skills.localization.motion import OdometryNoise
from mmexec.skills.localization.reflectors import ReflectorConfig, TriangleLibrary

__all__ = [
    "AmclConfig",
    "BeamModel",
    "Estimate",
    "LikelihoodField",
    "OdometryNoise",
    "ParticleFilter",
    "ReflectorConfig",
    "ReflectorMap",
    "TriangleLibrary",
    "load_reflectors",
]
