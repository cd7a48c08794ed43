"""The fetch-item skills (issue 5, seed paper: low-resource LoCoBot fetch architecture).

Importing this package registers ``detect_marker``, ``search``, ``navigate``,
``approach``, ``pick``, ``place`` and ``arm_pose`` in
:data:`mmexec.skills.base.REGISTRY`. They talk only to the capability interfaces, so
they run unchanged on the simulator and the real robot; robot-specific values come from
the profile's ``fetch:`` section (:class:`mmexec.skills.fetch.common.FetchProfile`).
See docs/fetch.md.
"""

from __future__ import annotations

from mmexec.skills.fetch import arm, detect, navigate, search
from mmexec.skills.fetch.common import FetchProfile, MarkerEstimate

__all__ = ["FetchProfile", "MarkerEstimate", "arm", "detect", "navigate", "search"]
