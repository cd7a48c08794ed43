"""Universal Robots e-series arm through ur_rtde.

Modules (import them directly; this package imports nothing heavy on purpose, so the
RTDE stub process starts fast):

* :mod:`mmexec.drivers.ur.rtde_codec`: pure RTDE wire-protocol functions over bytes.
* :mod:`mmexec.drivers.ur.rtde_stub`: an RTDE server stub run in a separate process,
  with fault injection, that the real ``rtde_receive.RTDEReceiveInterface`` connects to.
* :mod:`mmexec.drivers.ur.fake`: Python-level fakes of ``RTDEControlInterface`` and
  ``RTDEReceiveInterface`` sharing one fake controller state.
* :mod:`mmexec.drivers.ur.arm`: :class:`~mmexec.drivers.ur.arm.URArm`, the
  :class:`~mmexec.drivers.interfaces.Arm` adapter.
* :mod:`mmexec.drivers.ur.bringup`: ``mmexec hw ping ur`` and ``mmexec hw fake ur``.
"""
