"""The fetch-item mission's own skills (issue 5, seed paper: low-resource LoCoBot fetch
architecture): ``pick`` (the box tagged with the requested marker) and ``place`` (in the
depot basket), ``marker_grasp_frame`` and ``relocate_marker`` (the way to a marker whose
front is blocked, :mod:`mmexec.skills.fetch.holistic`), and the profile's ``fetch:`` section (the item, its grasp, the depot;
:class:`mmexec.skills.fetch.profile.FetchProfile`). See docs/fetch.md.

The rest of the mission is the general skill library, which importing this package
registers too: ``navigate``, ``back_off`` (:mod:`mmexec.skills.navigation.navigate`),
``approach`` (:mod:`mmexec.skills.navigation.approach`), ``search``
(:mod:`mmexec.skills.search`), ``detect_marker`` (:mod:`mmexec.skills.perception.detect`)
and ``arm_pose`` (:mod:`mmexec.skills.manipulation.arm`). They talk only to the capability
interfaces, so they run unchanged on the simulator and the real robot.
"""

from __future__ import annotations

from mmexec.skills import search
from mmexec.skills.fetch import arm, holistic, profile
from mmexec.skills.fetch.profile import FetchProfile
from mmexec.skills.manipulation import arm as arm_motion
from mmexec.skills.navigation import approach, navigate
from mmexec.skills.perception import detect

__all__ = ["FetchProfile", "approach", "arm", "arm_motion", "detect", "holistic", "navigate", "profile", "search"]
