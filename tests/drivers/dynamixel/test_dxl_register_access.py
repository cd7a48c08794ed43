"""Register access goes through the control tables: no raw addresses in the wx250s driver."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from mmexec.drivers.dynamixel import arm, bus, wx250s
from mmexec.drivers.dynamixel.control_table import (
    MODELS,
    TWO_XL430_W250,
    XL430_W250,
    XM430_W350,
    common_register,
)
from mmexec.drivers.dynamixel.wx250s import CycleIO

#: DxlBus calls that take a register address, and the position of the address argument
BUS_CALLS = {
    "read": 1,
    "read_status": 1,
    "write": 1,
    "reg_write": 1,
    "sync_read": 0,
    "sync_write": 0,
}
#: the expressions a DxlBus is called through (``self``: DxlBus's own methods)
BUS_RECEIVERS = {"bus", "self.bus", "self"}


def _raw_addresses(path: Path) -> list[str]:
    """``line: call`` for every bus call in ``path`` whose address is an integer literal or a
    module-level name bound to one (also through ``retry(bus.write, ...)``)."""
    tree = ast.parse(path.read_text())
    int_names = {
        t.id
        for node in tree.body
        if isinstance(node, ast.Assign)
        and isinstance(node.value, ast.Constant)
        and type(node.value.value) is int
        for t in node.targets
        if isinstance(t, ast.Name)
    }
    out = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call):
            continue
        func, args = node.func, node.args
        if args and isinstance(args[0], ast.Attribute) and args[0].attr in BUS_CALLS:
            func, args = args[0], args[1:]  # retry(bus.write, dxl_id, address, data)
        if not isinstance(func, ast.Attribute) or func.attr not in BUS_CALLS:
            continue
        if ast.unparse(func.value) not in BUS_RECEIVERS:
            continue  # os.read, link.write: not a servo register
        k = BUS_CALLS[func.attr]
        if len(args) <= k:
            continue
        a = args[k]
        if (isinstance(a, ast.Constant) and isinstance(a.value, int)) or (
            isinstance(a, ast.Name) and a.id in int_names
        ):
            out.append(f"{node.lineno}: {ast.unparse(node)}")
    return out


@pytest.mark.parametrize("module", [wx250s, bus], ids=lambda m: m.__name__.rsplit(".", 1)[-1])
def test_no_raw_register_addresses(module: object) -> None:
    path = Path(module.__file__)  # type: ignore[attr-defined]
    assert _raw_addresses(path) == []


def test_the_scan_finds_raw_addresses(tmp_path: Path) -> None:
    src = tmp_path / "raw.py"
    src.write_text(
        "GOAL = 116\n"
        "def f(bus, retry):\n"
        "    bus.write(1, 64, b'\\x01')\n"
        "    retry(bus.write, 1, 44, b'')\n"
        "    bus.sync_write(GOAL, 4, [])\n"
        "    bus.read(1, reg.address, reg.size)\n"
    )
    assert [line.split(":")[0] for line in _raw_addresses(src)] == ["3", "4", "5"]


def test_common_register() -> None:
    reg = common_register(MODELS.values(), "hardware_error_status")
    assert (reg.address, reg.size) == (70, 1)
    effort = common_register((XM430_W350, XL430_W250), lambda m: m.effort_register)
    assert (effort.address, effort.size) == (126, 2)
    with pytest.raises(ValueError, match="no models"):
        common_register((), "goal_pwm")
    with pytest.raises(KeyError, match="current_limit"):
        common_register((XM430_W350, XL430_W250), "current_limit")


def test_encode_uses_the_register_size() -> None:
    assert XM430_W350.encode("goal_position", 2048) == (2048).to_bytes(4, "little")
    assert XL430_W250.encode("goal_pwm", -200) == (-200 & 0xFFFF).to_bytes(2, "little")
    assert TWO_XL430_W250.encode("bus_watchdog", 5) == b"\x05"


def test_cycle_io_reads_the_present_block_of_the_tables() -> None:
    models = {1: XM430_W350, 9: XL430_W250}
    io = CycleIO(bus=None, write_ids=[1], read_ids=[1, 9], models=models)  # type: ignore[arg-type]
    assert io._block == (126, 12)
    assert io._goal.address == 116


def test_adapters_live_beside_the_device() -> None:
    assert arm.WX250sArm.__module__ == "mmexec.drivers.dynamixel.arm"
    assert arm.WX250sGripper.__module__ == "mmexec.drivers.dynamixel.arm"
    assert "WX250sArm" not in wx250s.__all__
