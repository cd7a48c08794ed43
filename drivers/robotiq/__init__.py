"""Robotiq 2F-85 adaptive gripper: Modbus RTU over RS-485 and the URCap socket (port 63352).

* :mod:`.codec`: pure Modbus RTU frames, register packing, command/status bytes, SI units;
* :mod:`.errors`: the package's exceptions (link errors, named faults, preconditions);
* :mod:`.core`: the I/O thread and goals shared by both links;
* :mod:`.device`: :class:`RobotiqModbus` on a serial port;
* :mod:`.urcap`: :class:`RobotiqURCap` through a UR controller's URCap socket;
* :mod:`.gripper`: :class:`RobotiqGripper`, the Gripper capability;
* :mod:`.bringup`: ``mmexec hw ping robotiq`` / ``mmexec hw fake robotiq``.
"""
