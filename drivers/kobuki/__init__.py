"""Kobuki (Yujin YMR-K01) mobile base driver: the LoCoBot's base.

* :mod:`.codec`: frames, feedback / command sub-payloads, (v, w) conversion, odometry
  (pure functions over bytes);
* :mod:`.device`: :class:`~.device.KobukiDevice`, the serial link and its I/O thread;
* :mod:`.base`: :class:`~.base.KobukiBase`, the :class:`mmexec.drivers.interfaces.Base`
  capability;
* :mod:`.bringup`: ``mmexec hw ping kobuki`` / ``mmexec hw fake kobuki``.

See docs/drivers/kobuki.md.
"""
