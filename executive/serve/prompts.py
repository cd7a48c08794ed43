"""Operator channels for ``ask_operator`` (:mod:`mmexec.skills.operator`).

* :class:`PromptBoard`: ``mmexec serve``; prompts are shown to the console and the API,
  answers arrive from the HTTP thread.
* :class:`ScriptedAnswers`: ``mmexec run --answers FILE``; a YAML list of answers, one per
  prompt, in order.
* :class:`TerminalOperator`: ``mmexec run`` on a terminal; the question is printed and
  the answer typed, read without blocking the tick.

A stepped clock (the simulator) runs faster than a person reads; while a prompt waits
for a person, :meth:`PromptBoard.pace` and :meth:`TerminalOperator.pace` (runner tick
hooks) hold each tick to the wall-clock period, so a prompt's timeout is in seconds a
person can use.
"""

from __future__ import annotations

import logging
import math
import os
import select
import tempfile
import threading
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

from mmexec.config.yamlload import InputError, Mark, Problem, YDict, YList, load_yaml
from mmexec.drivers.interfaces import Robot
from mmexec.executive.textsafe import printable
from mmexec.skills.operator import KINDS, Answer, AnswerError, Prompt, validate_answer

__all__ = [
    "PromptAnsweredError",
    "PromptBoard",
    "PromptClosedError",
    "ScriptedAnswer",
    "ScriptedAnswers",
    "TerminalOperator",
    "load_answers",
]

log = logging.getLogger(__name__)


class PromptClosedError(LookupError):
    """The prompt is not open (never asked, timed out, cancelled, answered and closed)."""


class PromptAnsweredError(PromptClosedError):
    """The prompt has an answer already (the first answer counts)."""


class PromptBoard:
    """The service's operator channel: open prompts, answered from any thread.

    ``notify(kind, data)`` is called on every change: ``prompt`` (the prompt's JSON),
    ``prompt_answered`` and ``prompt_closed`` (``id``, ``reason``).
    """

    def __init__(self, notify: Callable[[str, dict[str, Any]], None] | None = None) -> None:
        self._notify = notify
        self._lock = threading.Lock()
        self._open: dict[str, Prompt] = {}
        self._answers: dict[str, Answer] = {}
        self._answered = threading.Event()

    # tick thread
    def ask(self, prompt: Prompt) -> None:
        with self._lock:
            self._open[prompt.id] = prompt
        self._emit("prompt", prompt.to_json())

    def poll(self, prompt_id: str, now: float) -> Answer | None:
        with self._lock:
            return self._answers.get(prompt_id)

    def close(self, prompt_id: str, reason: str) -> None:
        with self._lock:
            self._open.pop(prompt_id, None)
            self._answers.pop(prompt_id, None)
        self._emit("prompt_closed", {"id": prompt_id, "reason": reason})

    def pace(self, robot: Robot, period: float) -> None:
        """Tick hook: on a stepped clock, while a prompt waits, spend ``period`` of wall
        time (less when an answer arrives) so the clock keeps pace with the operator."""
        if robot.clock.stepped and self.waiting():
            self._answered.wait(period)
            self._answered.clear()

    # any thread
    def answer(self, prompt_id: str, value: Any, source: str) -> Any:
        """Answer an open prompt; returns the converted value. Raises
        :class:`PromptClosedError` (not open, or answered already) or
        :class:`~mmexec.skills.operator.AnswerError` (the value does not fit)."""
        with self._lock:
            prompt = self._open.get(prompt_id)
            if prompt is None:
                raise PromptClosedError(f"prompt {prompt_id!r} is not open (answered, timed out, cancelled, "
                                        "or never asked)")
            if prompt_id in self._answers:
                raise PromptAnsweredError(f"prompt {prompt_id!r} was answered already")
            converted = validate_answer(prompt, value)
            self._answers[prompt_id] = Answer(converted, source)
        self._answered.set()
        self._emit("prompt_answered", {"id": prompt_id, "answer": converted, "source": source})
        return converted

    def open_prompts(self) -> list[Prompt]:
        with self._lock:
            return [p for pid, p in self._open.items() if pid not in self._answers]

    def get(self, prompt_id: str) -> Prompt | None:
        with self._lock:
            return self._open.get(prompt_id)

    def waiting(self) -> bool:
        """Whether a prompt waits for an answer."""
        with self._lock:
            return any(pid not in self._answers for pid in self._open)

    def _emit(self, kind: str, data: dict[str, Any]) -> None:
        if self._notify is not None:
            self._notify(kind, data)


# --------------------------------------------------------------------------- --answers FILE


@dataclass(frozen=True)
class ScriptedAnswer:
    """One entry of an answers file: the ``value``, where it is written (``mark``), the
    prompt ``kind`` it was written for (None: any) and ``after`` [clock s] since the
    prompt was asked."""

    value: Any
    mark: Mark
    kind: str | None = None
    after: float = 0.0


_ENTRY_KEYS = ("answer", "kind", "after")


def _entry(item: Any, mark: Mark, i: int, problems: list[Problem]) -> ScriptedAnswer | None:
    where = f"answer {i + 1}"
    if not isinstance(item, YDict):
        if item is None or isinstance(item, (bool, int, float, str, list)):
            return ScriptedAnswer(list(item) if isinstance(item, list) else item, mark)
        problems.append(Problem(mark, f"{where}: expected an answer or a mapping with 'answer', got {item!r}"))
        return None
    found = [Problem(item.key_mark(k), f"{where}: unknown key {k!r} (expected {', '.join(_ENTRY_KEYS)})")
             for k in item if k not in _ENTRY_KEYS]
    if "answer" not in item:
        found.append(Problem(mark, f"{where}: missing 'answer'"))
    kind = item.get("kind")
    if kind is not None and kind not in KINDS:
        found.append(Problem(item.value_mark("kind"), f"{where}: kind must be one of {list(KINDS)}, got {kind!r}"))
    after = item.get("after", 0.0)
    if (not isinstance(after, (int, float)) or isinstance(after, bool) or not math.isfinite(after)
            or after < 0):
        found.append(Problem(item.value_mark("after"), f"{where}: after: expected clock seconds >= 0, got {after!r}"))
    if found:
        problems.extend(found)
        return None
    value = item["answer"]
    return ScriptedAnswer(list(value) if isinstance(value, list) else value, mark, kind, float(after))


def load_answers(path: str | Path) -> list[ScriptedAnswer]:
    """Read an answers file: a YAML list, one entry per prompt in the order they are
    asked; an entry is the answer itself (``yes``, ``shelf``, ``[320, 240]``) or a mapping
    ``{answer: ..., kind: confirm|choose|point, after: S}``. Raises InputError (located)."""
    data = load_yaml(path)
    if not isinstance(data, YList):
        raise InputError.at(getattr(data, "mark", Mark(str(path), 1, 1)),
                            "expected a YAML list of answers, e.g. '- yes' or '- {answer: [320, 240], after: 2}'")
    problems: list[Problem] = []
    out = [_entry(item, data.item_mark(i), i, problems) for i, item in enumerate(data)]
    if problems:
        raise InputError(problems)
    return [e for e in out if e is not None]


class ScriptedAnswers:
    """``--answers FILE``: the i-th prompt of the run gets the i-th entry, ``after`` clock
    seconds after it was asked. A prompt with no entry left, an entry written for another
    kind, or a value that does not fit fails the skill with the entry's location."""

    source = "script"

    def __init__(self, answers: list[ScriptedAnswer], path: str | Path) -> None:
        self.answers = answers
        self.path = str(path)
        self._next = 0
        self._assigned: dict[str, tuple[Prompt, int]] = {}

    def ask(self, prompt: Prompt) -> None:
        self._assigned[prompt.id] = (prompt, self._next)
        self._next += 1

    def poll(self, prompt_id: str, now: float) -> Answer | None:
        prompt, i = self._assigned[prompt_id]
        if i >= len(self.answers):
            raise AnswerError(f"{self.path}: no answer left for prompt {i + 1} ({prompt.text!r}): "
                              f"the file has {len(self.answers)}")
        entry = self.answers[i]
        if entry.kind is not None and entry.kind != prompt.kind:
            raise AnswerError(f"{entry.mark}: answer {i + 1} is for a {entry.kind} prompt, "
                              f"but prompt {i + 1} ({prompt.text!r}) is a {prompt.kind}")
        if now < prompt.asked_at + entry.after:
            return None
        try:
            return Answer(validate_answer(prompt, entry.value), self.source)
        except AnswerError as e:
            raise AnswerError(f"{entry.mark}: answer {i + 1}: {e}") from None

    def close(self, prompt_id: str, reason: str) -> None:
        self._assigned.pop(prompt_id, None)


# --------------------------------------------------------------------------- terminal


class TerminalOperator:
    """Asks on a terminal: prints the question on ``out`` and reads the answer from the
    file descriptor ``fd`` (standard input) without blocking: each poll reads only what
    is already typed. Point prompts save the image (with nothing drawn) under
    ``image_dir`` and name the file. End of input fails the waiting skill."""

    source = "terminal"

    def __init__(self, fd: int, out: TextIO, *, image_dir: Path | None = None, progress: Any = None) -> None:
        self.fd = fd
        self.out = out
        self.image_dir = image_dir
        self.progress = progress  # the run's status line (a Progress), kept off while a prompt waits
        self._progress_was = False
        self._buffer = b""
        self._eof = False
        self._open: dict[str, Prompt] = {}

    def ask(self, prompt: Prompt) -> None:
        if self.progress is not None and not self._open:
            self.progress.clear()
            self._progress_was, self.progress.enabled = self.progress.enabled, False
        self._open[prompt.id] = prompt
        lines = [f"operator: {prompt.text}"]
        if prompt.kind == "choose":
            lines += [f"  {i}) {opt}" for i, opt in enumerate(prompt.options, start=1)]
        if prompt.image is not None:
            lines.append(f"  image: {self._save_image(prompt)}")
        lines.append(f"  answer {self._hint(prompt)}"
                     + (f" within {prompt.timeout:g} s" if prompt.timeout is not None else "") + ": ")
        self._say("\n".join(lines))

    def poll(self, prompt_id: str, now: float) -> Answer | None:
        prompt = self._open[prompt_id]
        self._read_available()
        while b"\n" in self._buffer:
            raw, self._buffer = self._buffer.split(b"\n", 1)
            text = raw.decode("utf-8", errors="replace").strip()
            try:
                return Answer(validate_answer(prompt, self._parse(prompt, text)), self.source)
            except AnswerError as e:
                self._say(f"operator: {e}; answer {self._hint(prompt)}: ")
        if self._eof:
            raise AnswerError(f"the terminal's input ended before prompt {prompt.id} was answered")
        return None

    def close(self, prompt_id: str, reason: str) -> None:
        if self._open.pop(prompt_id, None) is not None and reason not in ("answered", "declined"):
            self._say(f"operator: prompt withdrawn ({reason})")
        if self.progress is not None and not self._open:
            self.progress.enabled = self._progress_was

    def pace(self, robot: Robot, period: float) -> None:
        """Tick hook: on a stepped clock, while a prompt waits, wait up to ``period`` of
        wall time for typing (returns early when a key arrives)."""
        if robot.clock.stepped and self._open and not self._eof:
            select.select([self.fd], [], [], period)

    def _read_available(self) -> None:
        while not self._eof:
            ready, _, _ = select.select([self.fd], [], [], 0.0)
            if not ready:
                return
            chunk = os.read(self.fd, 4096)
            if not chunk:
                self._eof = True
                if self._buffer:
                    self._buffer += b"\n"  # a last line without a newline still counts
                return
            self._buffer += chunk

    @staticmethod
    def _hint(prompt: Prompt) -> str:
        if prompt.kind == "confirm":
            return "y or n"
        if prompt.kind == "choose":
            return f"1..{len(prompt.options)} or the option's text"
        size = prompt.image_size
        return "u v (pixels" + (f", image {size[0]}x{size[1]})" if size else ")")

    @staticmethod
    def _parse(prompt: Prompt, text: str) -> Any:
        if prompt.kind == "choose" and text.isdigit() and 1 <= int(text) <= len(prompt.options):
            return prompt.options[int(text) - 1]
        if prompt.kind == "point":
            parts = text.replace(",", " ").split()
            try:
                return [float(p) for p in parts]
            except ValueError:
                return text
        return text

    def _save_image(self, prompt: Prompt) -> str:
        assert prompt.image is not None
        folder = self.image_dir if self.image_dir is not None else Path(tempfile.mkdtemp(prefix="mmexec-prompts-"))
        self.image_dir = folder
        path = folder / f"{prompt.id}.jpg"
        path.write_bytes(prompt.image)
        return str(path)

    def _say(self, text: str) -> None:
        self.out.write(printable(text, multiline=True) + "\n")
        self.out.flush()
