"""A bad wx250s arm section is one located line: the wx250s gripper that depends on it does
not add a second, misleading one ("needs 'arm: {kind: wx250s}'")."""

from __future__ import annotations

from pathlib import Path

import pytest
from test_dxl_safety import RATES, validate_locobot_with


@pytest.mark.parametrize(("key", "value", "message"), [
    ("baudrate", "-5", f"baudrate: -5 bit/s is not a DYNAMIXEL baud rate ({RATES})"),
    ("rate_hz", "0", "rate_hz: must be in (0, 1000], got 0.0"),
])
def test_bad_arm_section_is_one_line(
    key: str, value: str, message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, lines, kind_line = validate_locobot_with(tmp_path, capsys, key, value)
    assert code == 2
    assert lines == [f"{tmp_path / 'locobot.yaml'}:{kind_line}:5: robot.arm: {message}"]
