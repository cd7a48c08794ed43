"""Robotiq 2F-85 adaptive gripper facts (docs/robots.md 2.4), as modelled for planning and
simulation: two prismatic pads on a coupling, closing along +-y of the gripper frame.

Lengths m, forces N, speeds m/s.
"""

from __future__ import annotations

from mmexec.drivers.descriptions.linktree import DARK, LIGHT, Geom, LinkTree

__all__ = ["COUPLING", "FORCE", "PAD_Z", "SPEED", "STROKE", "TCP_Z", "add_gripper"]

COUPLING = 0.011  # m, flange to the gripper base
STROKE = 0.085    # m, pad gap when open
PAD_Z = 0.137     # m, pad centre above the gripper base (between open/closed)
TCP_Z = 0.144     # m, closed-grasp point above the gripper base
SPEED = 0.150     # m/s, pad gap closing speed
FORCE = 235.0     # N, grip force


def add_gripper(m: LinkTree, parent: str) -> None:
    """Add the gripper to ``m``: ``robotiq_base_link`` on a :data:`COUPLING` along the
    z of ``parent`` (the flange frame, ``tool0``), pads ``left_pad_link`` /
    ``right_pad_link`` on the joints ``left_pad_joint`` / ``right_pad_joint`` (value =
    closing travel of the pad: 0 open ... STROKE/2 closed), and ``robotiq_tcp``."""
    m.link("robotiq_base_link", (
        Geom("cylinder", (0.0375, 0.011), (0.0, 0.0, -0.0055), rgba=DARK),
        Geom("box", (0.065, 0.13, 0.095), (0.0, 0.0, 0.0475), rgba=DARK),
    ), mass=0.9, com=(0.0, 0.0, 0.05))
    m.joint("robotiq_coupling", "fixed", parent, "robotiq_base_link", (0.0, 0.0, COUPLING))
    half = STROKE / 2
    for side, sgn in (("left", 1.0), ("right", -1.0)):
        m.link(f"{side}_pad_link", (
            Geom("box", (0.022, 0.00635, 0.0375), (0.0, sgn * 0.003175, 0.0), rgba=LIGHT),
            Geom("box", (0.022, 0.012, 0.05), (0.0, sgn * 0.012, -0.04), rgba=DARK, collide=False),
        ), mass=0.05, com=(0.0, sgn * 0.003175, 0.0))
        m.joint(f"{side}_pad_joint", "prismatic", "robotiq_base_link", f"{side}_pad_link",
                (0.0, sgn * half, PAD_Z), axis=(0.0, -sgn, 0.0), lower=0.0, upper=half,
                velocity=0.075, effort=117.5)
    m.link("robotiq_tcp", (), mass=0.001)
    m.joint("robotiq_tcp_joint", "fixed", "robotiq_base_link", "robotiq_tcp", (0.0, 0.0, TCP_Z))
