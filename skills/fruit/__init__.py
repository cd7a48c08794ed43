"""The fruit-picking mission's skills (issue 14, thesis ros2-thesis-follower-buttons-fruit
section 1.3): detect fruit in the wrist camera's image, fit each one's barycentre,
choose by priority, grasp by the thesis's candidates, pull it off its branch and drop it
into a basket (docs/fruit.md). The profile's ``fruit:`` section is
:class:`mmexec.skills.fruit.profile.FruitProfile`.
"""

from __future__ import annotations

from mmexec.skills.fruit import pick, profile
from mmexec.skills.fruit.profile import FruitProfile

__all__ = ["FruitProfile", "pick", "profile"]
