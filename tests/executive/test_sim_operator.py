"""The scripted sim operator's answers file (executive/sim_operator.py): a 'sim_click:'
mapping makes one, a list of answers does not, mistakes are located, a prompt it cannot
answer fails the skill with one line."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import pytest

from mmexec.config.yamlload import InputError
from mmexec.executive.sim_operator import SimClickOperator, sim_click_operator
from mmexec.skills.operator import AnswerError, OverlayShape, Prompt


def _file(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "answers.yaml"
    p.write_text(text)
    return p


def test_a_sim_click_file_makes_the_operator_and_a_list_does_not(tmp_path: Path) -> None:
    op = sim_click_operator(_file(tmp_path, "sim_click: {noise_px: 2, after: 0.5}\n"), lambda: None, 3)
    assert isinstance(op, SimClickOperator) and op.settings.noise_px == 2 and op.settings.part == "dangerous"
    assert sim_click_operator(_file(tmp_path, "- yes\n- [1, 2]\n"), lambda: None, 3) is None


@pytest.mark.parametrize(("text", "message"), [
    ("sim_click: {noise_px: -1}\n", "noise_px"),
    ("sim_click: {after: soon}\n", "after"),
    ("sim_click: {noise: 3}\n", "did you mean 'noise_px'"),
])
def test_mistakes_are_located(tmp_path: Path, text: str, message: str) -> None:
    with pytest.raises(InputError) as e:
        sim_click_operator(_file(tmp_path, text), lambda: None, 0)
    assert message in str(e.value) and "answers.yaml:1:" in str(e.value)


def test_a_prompt_it_cannot_answer_fails_with_one_line(tmp_path: Path) -> None:
    op = sim_click_operator(_file(tmp_path, "sim_click: {}\n"), lambda: SimpleNamespace(), 0)
    assert op is not None
    op.ask(Prompt(id="p1", kind="confirm", text="ok?"))
    with pytest.raises(AnswerError, match="point prompts only"):
        op.poll("p1", 10.0)
    op.ask(Prompt(id="p2", kind="point", text="where?", image_size=(64, 48),
                  overlay=(OverlayShape("box", ((1.0, 1.0), (9.0, 9.0))),)))
    with pytest.raises(AnswerError, match="needs the simulator"):
        op.poll("p2", 10.0)
