"""Slamtec RPLIDAR A2 (A2M8) 360 degree laser scanner driver: the LoCoBot's lidar.

* :mod:`.codec`: requests, response descriptors, info / health / sample rate, scan
  measurement nodes (pure functions over bytes);
* :mod:`.scan`: one revolution of nodes into a fixed CCW grid (pure, numpy);
* :mod:`.device`: :class:`~.device.RplidarDevice`, the serial link, the motor (DTR and
  SET_MOTOR_PWM), the reader thread and its watchdog;
* :mod:`.lidar`: :class:`~.lidar.RplidarLidar`, the
  :class:`mmexec.drivers.interfaces.Lidar` capability;
* :mod:`.bringup`: ``mmexec hw ping rplidar`` / ``mmexec hw fake rplidar``.

See docs/drivers/rplidar.md.
"""
