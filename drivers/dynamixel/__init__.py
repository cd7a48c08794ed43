"""Interbotix WX250s arm (and LoCoBot pan/tilt) over DYNAMIXEL Protocol 2.0.

Layers: :mod:`.codec` (pure framing), :mod:`.control_table` (register maps as data, unit
conversions, fault names), :mod:`.bus` (half-duplex bus with link-derived deadlines),
:mod:`.model` (the WX250s servo facts), :mod:`.wx250s` (the arm device and its I/O
thread), :mod:`.arm` (its Arm/Gripper capability adapters),
:mod:`.bringup` (``mmexec hw ping|fake dynamixel``). See docs/drivers/dynamixel.md.
"""
