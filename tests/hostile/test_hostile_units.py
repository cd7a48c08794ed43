"""Unit tests behind the hostile-input corpus: the typed float binding, the regular-file
reader, the terminal-text escaping, the live status line, and the primitives' own
refusal of non-finite numbers (defence in depth behind the mission loader)."""

from __future__ import annotations

import io
import math
from dataclasses import dataclass
from pathlib import Path

import pytest

import mmexec.skills.primitives  # noqa: F401 - registers the primitives
from mmexec.config.yamlload import (
    InputError,
    Mark,
    MaybeInfinite,
    Problems,
    bind,
    load_yaml_text,
    read_file,
)
from mmexec.executive.compiler import convert_value
from mmexec.executive.runner import Progress
from mmexec.executive.textsafe import printable
from mmexec.skills.base import FailureKind, SkillStatus

HERE = Mark("t.yaml", 1, 1)


@dataclass(frozen=True)
class _Limits:
    period: float
    patience: MaybeInfinite = 1.0


def _bind(text: str) -> tuple[object, list[str]]:
    problems = Problems()
    out = bind(_Limits, load_yaml_text(text, "t.yaml"), HERE, "", problems)
    return out, [str(p) for p in problems]


@pytest.mark.parametrize(("text", "problem"), [
    ("period: .nan", "t.yaml:1:9: period: expected a finite number, got .nan"),
    ("period: -.inf", "t.yaml:1:9: period: expected a finite number, got -.inf"),
    ("period: " + "9" * 400, "t.yaml:1:9: period: expected a finite number, got an integer too large for a float"),
    ("period: 1\npatience: .nan", "t.yaml:2:11: patience: expected a finite number, got .nan"),
])
def test_a_float_field_refuses_non_finite_numbers(text: str, problem: str) -> None:
    out, problems = _bind(text)
    assert out is None and problems == [problem]


def test_a_field_declared_maybe_infinite_takes_infinity_but_never_nan() -> None:
    out, problems = _bind("period: 0.5\npatience: .inf")
    assert problems == [] and out == _Limits(0.5, math.inf)


def test_untyped_data_is_scanned_for_non_finite_numbers_once_per_alias() -> None:
    doc = load_yaml_text("a: &x {q: [1.0, .nan]}\nb: *x\nc: *x\n", "t.yaml")
    problems = Problems()
    bind(dict, doc, HERE, "profile", problems)
    assert [str(p) for p in problems] == ["t.yaml:1:17: profile.a.q[1]: expected a finite number, got .nan"]


@pytest.mark.parametrize("text", ["nan", "inf", "-inf", "1e999", "[1, .nan]", "{a: [.inf]}"])
def test_command_line_values_refuse_non_finite_numbers(text: str) -> None:
    tp = {"[": list, "{": dict}.get(text[0], float)
    with pytest.raises(ValueError, match="expected a finite number"):
        convert_value(tp, text, "parameter 'p'")


def test_read_file_stops_one_byte_past_the_limit(tmp_path: Path) -> None:
    p = tmp_path / "f.yaml"
    p.write_bytes(b"a" * 10)
    assert read_file(p, limit=10) == b"a" * 10
    with pytest.raises(InputError, match=r"f.yaml:1:1: file is 10 bytes, larger than the 9 byte limit"):
        read_file(p, limit=9)


def test_printable_escapes_controls_and_keeps_text() -> None:
    assert printable("café ok") == "café ok"
    assert printable("a\x1b[2Jb\x9bc\u202ed\re\n") == "a\\x1b[2Jb\\x9bc\\u202ed\\re\\n"
    assert printable("row 1\n\trow 2\x07", multiline=True) == "row 1\n\trow 2\\x07"


def test_the_live_status_line_escapes_node_paths() -> None:
    screen = io.StringIO()
    Progress(screen, enabled=True, interval=0.0).update("[1/1] 0.0 s  mission/\x1b]0;owned\x07")
    assert screen.getvalue() == "\r[1/1] 0.0 s  mission/\\x1b]0;owned\\x07\x1b[K"


@pytest.mark.parametrize(("skill", "params"), [
    ("drive_to", {"x": math.nan, "y": 0.0}),
    ("drive_to", {"x": 1.0, "y": 0.0, "timeout": math.nan}),
    ("drive_to", {"x": 1.0, "y": 0.0, "max_linear": math.inf}),
    ("wait", {"seconds": math.inf}),
    ("wait", {"seconds": math.nan}),
    ("move_arm", {"joints": [0.0, math.nan, 0.0, 0.0, 0.0, 0.0]}),
    ("open_gripper", {"width": math.nan}),
    ("close_gripper", {"force": math.inf}),
])
def test_primitives_refuse_non_finite_numbers_that_reach_them(run_mock_skill, mock_robot, skill: str,
                                                              params: dict) -> None:
    """A NaN goal once drove the mock base at full speed forever; ``wait .nan`` succeeded
    at once and ``wait .inf`` never ended. Such values can still arrive through the
    blackboard: each primitive fails with PRECONDITION before commanding anything."""
    run = run_mock_skill(skill, params, max_ticks=200)
    assert run.status is SkillStatus.FAILURE
    assert run.failure.kind is FailureKind.PRECONDITION and "must be a finite number" in run.failure.reason
    assert mock_robot.base.state().v == 0.0
