"""The fetch_object mission's skills (issue 15; paper locobot-holistic-planning-dangerous-
objects): fetch an ordinary, untagged object by name. ``find_object`` (likely places from
the catalogue, then the search locations), ``approach_object`` (a stand-off from the
object's support), ``locate_object`` (the closest view), ``mark_dangerous`` (the operator's
click on a dangerous item's dangerous part moves the grasp), ``pick_object`` (top or front
grasp at the estimated centre of mass), and the profile's ``fetch_object:`` section
(:mod:`.profile`). The depot, ``place`` and the general skills come from the fetch
package, which importing this one registers too. See docs/fetch_object.md.
"""

from __future__ import annotations

from mmexec.skills import fetch
from mmexec.skills.fetch_object import detector, profile, skills
from mmexec.skills.fetch_object.profile import FetchObjectSettings

__all__ = ["FetchObjectSettings", "detector", "fetch", "profile", "skills"]
