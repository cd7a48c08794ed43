"""UR controller state codes (ur_rtde 1.6.5 docstrings, docs/protocols.md 4.2) and their meaning.

Pure data and functions, no imports beyond the standard library, so the RTDE stub
process, the ping and the arm adapter share one copy of the vendor's numbering:

* robot mode (``getRobotMode()`` / RTDE ``robot_mode``): -1 no controller ... 7 running;
* safety mode (``getSafetyMode()`` / ``safety_mode``): 1 normal ... 13 three-position-enabling stop;
* safety status bits (``getSafetyStatusBits()`` / ``safety_status_bits``): bit 0 normal,
  1 reduced, 2 protective stopped, 3 recovery, 4 safeguard stopped, 5 system e-stop,
  6 robot e-stop, 7 e-stopped, 8 violation, 9 fault, 10 stopped due to safety;
* runtime state (``getRuntimeState()`` / ``runtime_state``): 0 stopping ... 5 resuming;
* robot status bits (``getRobotStatus()`` / ``robot_status_bits``): bit 0 power on,
  1 program running, 2 teach button, 3 power button.

The vendor gives the two bit fields and the two mode fields separately; which bits go
with which safety mode (:func:`safety_status_bits`) and when the power-on bit is set
(:func:`robot_status_bits`) is derived here for the fakes, from the names.
"""

from __future__ import annotations

__all__ = [
    "ROBOT_MODES",
    "ROBOT_MODE_RUNNING",
    "RUNTIME_PLAYING",
    "RUNTIME_STATES",
    "SAFETY_MODES",
    "not_fit_reason",
    "robot_status_bits",
    "running_fault",
    "safety_fault",
    "safety_status_bits",
]

ROBOT_MODES: dict[int, str] = {
    -1: "no controller", 0: "disconnected", 1: "confirm safety", 2: "booting", 3: "power off",
    4: "power on", 5: "idle", 6: "backdrive", 7: "running", 8: "updating firmware",
}
SAFETY_MODES: dict[int, str] = {
    1: "normal", 2: "reduced", 3: "protective stop", 4: "recovery", 5: "safeguard stop",
    6: "system emergency stop", 7: "robot emergency stop", 8: "violation", 9: "fault",
    10: "validate joint id", 11: "undefined", 12: "automatic-mode safeguard stop",
    13: "three-position-enabling stop",
}
RUNTIME_STATES: dict[int, str] = {0: "stopping", 1: "stopped", 2: "playing", 3: "pausing", 4: "paused", 5: "resuming"}

ROBOT_MODE_RUNNING = 7
RUNTIME_PLAYING = 2

_BIT_PROTECTIVE, _BIT_ESTOPPED = 2, 7
#: safety mode -> its safety status bits (derived from the bit names; 10-13 have no bit of
#: their own and are reported as "stopped due to safety", bit 10)
_SAFETY_BITS: dict[int, int] = {
    1: 1 << 0, 2: 1 << 1, 3: 1 << 2, 4: 1 << 3, 5: 1 << 4, 6: (1 << 5) | (1 << 7), 7: (1 << 6) | (1 << 7),
    8: 1 << 8, 9: 1 << 9, 10: 1 << 10, 11: 1 << 10, 12: 1 << 4, 13: 1 << 4,
}
#: what the operator does about each robot mode that is not "running"
_ROBOT_MODE_REMEDY: dict[int, str] = {
    -1: "start the controller", 0: "connect the arm to the controller",
    1: "confirm the safety configuration on the pendant", 2: "wait for the controller to boot",
    3: "power the arm on and release the brakes on the pendant",
    4: "wait for power-on, then release the brakes on the pendant",
    5: "release the brakes on the pendant", 6: "leave backdrive mode on the pendant",
    8: "wait for the firmware update to finish",
}


def safety_status_bits(safety_mode: int) -> int:
    """The ``safety_status_bits`` a controller in ``safety_mode`` reports (derived)."""
    try:
        return _SAFETY_BITS[safety_mode]
    except KeyError:
        raise ValueError(f"unknown safety mode {safety_mode} (known: {min(SAFETY_MODES)}..{max(SAFETY_MODES)})") from None


def robot_status_bits(robot_mode: int, runtime_state: int) -> int:
    """``robot_status_bits``: bit 0 power on (robot modes 4 power on .. 7 running, derived),
    bit 1 program running (runtime state 2, playing)."""
    if robot_mode not in ROBOT_MODES:
        raise ValueError(f"unknown robot mode {robot_mode} (known: {min(ROBOT_MODES)}..{max(ROBOT_MODES)})")
    if runtime_state not in RUNTIME_STATES:
        raise ValueError(f"unknown runtime state {runtime_state} (known: 0..{max(RUNTIME_STATES)})")
    return (1 if 4 <= robot_mode <= 7 else 0) | (2 if runtime_state == RUNTIME_PLAYING else 0)


def safety_fault(safety_mode: int, safety_bits: int) -> str:
    """Why the safety system does not let the arm move, or "" (normal and reduced are fine)."""
    if safety_mode == 3 or safety_bits & (1 << _BIT_PROTECTIVE):
        return "protective stop"
    if safety_mode in (6, 7) or safety_bits & (1 << _BIT_ESTOPPED):
        return f"emergency stop ({SAFETY_MODES.get(safety_mode, safety_mode)})"
    if safety_mode in (5, 12, 13):
        return f"safeguard stop ({SAFETY_MODES[safety_mode]})"
    if safety_mode not in (1, 2):
        return f"safety fault (safety mode {safety_mode}: {SAFETY_MODES.get(safety_mode, 'unknown')})"
    return ""


def running_fault(robot_mode: int, safety_mode: int, safety_bits: int, runtime_state: int) -> str:
    """Why a connected arm (our control script running) cannot move now, or ""."""
    fault = safety_fault(safety_mode, safety_bits)
    if fault:
        return fault
    if runtime_state != RUNTIME_PLAYING:
        return f"program stopped (runtime state {runtime_state}: {RUNTIME_STATES.get(runtime_state, 'unknown')})"
    if robot_mode != ROBOT_MODE_RUNNING:
        return f"robot not running (robot mode {robot_mode}: {ROBOT_MODES.get(robot_mode, 'unknown')})"
    return ""


def not_fit_reason(robot_mode: int, safety_mode: int, safety_bits: int) -> str:
    """Why the driver could not start on this controller now, with the remedy, or "".

    Before bring-up no program needs to run: ``RTDEControlInterface`` uploads and starts
    its own control script, so the runtime state is not judged here. The arm must be
    powered with the brakes released (robot mode 7) and the safety system normal or
    reduced."""
    fault = safety_fault(safety_mode, safety_bits)
    if fault:
        remedy = ("unlock it on the pendant" if fault == "protective stop"
                  else "release the emergency stop button, then reset on the pendant" if fault.startswith("emergency")
                  else "clear the safeguard input" if fault.startswith("safeguard")
                  else "see the pendant's safety log")
        return f"{fault}: {remedy}"
    if robot_mode != ROBOT_MODE_RUNNING:
        name = ROBOT_MODES.get(robot_mode, "unknown")
        return f"robot mode {robot_mode} ({name}): {_ROBOT_MODE_REMEDY.get(robot_mode, 'check the pendant')}"
    return ""
