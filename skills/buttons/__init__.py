"""The button presser mission's skills (issue 14, the ROS 2 thesis's section 1.2):
``find_panel`` (the searching movement for the locator marker), ``approach_panel`` (park
in front of the panel), ``locate_panel`` (look at its markers, fit its frame) and
``press_buttons`` (straight-line presses, each light checked with the camera), and the
profile's ``buttons:`` section (:class:`~mmexec.skills.buttons.profile.ButtonsSettings`).
See docs/buttons.md.

The rest of the mission is the general skill library, which importing this package
registers too: ``arm_pose`` (:mod:`mmexec.skills.manipulation.arm`), ``navigate``
(:mod:`mmexec.skills.navigation.navigate`), ``report``.
"""

from __future__ import annotations

from mmexec.skills.buttons import lights, panel, profile
from mmexec.skills.buttons.profile import ButtonsSettings
from mmexec.skills.manipulation import arm as arm_motion
from mmexec.skills.navigation import navigate

__all__ = ["ButtonsSettings", "arm_motion", "lights", "navigate", "panel", "profile"]
