"""The node library: control flow, decorators, the skill leaf and the recovery node.

Split as py_trees is (one concept per module):

* :mod:`~mmexec.executive.nodes.behaviour`: the base :class:`MissionNode` with the
  halt contract, the tree's :class:`Runtime` (blackboard, context, listeners) and
  :class:`NodeError`;
* :mod:`~mmexec.executive.nodes.composites`: :class:`Sequence`, :class:`Fallback`,
  :class:`Parallel`, :class:`IfThenElse`;
* :mod:`~mmexec.executive.nodes.decorators`: :class:`Invert`, :class:`ForceSuccess`,
  :class:`ForceFailure`, :class:`Retry`, :class:`Repeat`, :class:`Foreach`,
  :class:`Timeout` and :class:`Subtree` (an include);
* :mod:`~mmexec.executive.nodes.leaves`: :class:`Wait`, :class:`Condition`,
  :class:`SkillLeaf`;
* :mod:`~mmexec.executive.nodes.recovery`: :class:`Recovery`.

Every name is importable from this package (``from mmexec.executive.nodes import X``).
"""

from __future__ import annotations

from mmexec.executive.nodes.behaviour import MissionNode, NodeError, Runtime, running_tip
from mmexec.executive.nodes.composites import Fallback, IfThenElse, Parallel, Sequence
from mmexec.executive.nodes.decorators import (
    ForceFailure,
    ForceSuccess,
    Foreach,
    Invert,
    Repeat,
    Retry,
    Subtree,
    Timeout,
)
from mmexec.executive.nodes.leaves import Condition, SkillLeaf, Wait
from mmexec.executive.nodes.recovery import Recovery

__all__ = [
    "Condition",
    "Fallback",
    "ForceFailure",
    "ForceSuccess",
    "Foreach",
    "IfThenElse",
    "Invert",
    "MissionNode",
    "NodeError",
    "Parallel",
    "Recovery",
    "Repeat",
    "Retry",
    "Runtime",
    "Sequence",
    "SkillLeaf",
    "Subtree",
    "Timeout",
    "Wait",
    "running_tip",
]
