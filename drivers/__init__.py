"""Capability interfaces (:mod:`mmexec.drivers.interfaces`) and the real hardware drivers."""
