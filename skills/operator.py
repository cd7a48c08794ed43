"""Asking the operator: the ``ask_operator`` skill and the one prompt mechanism behind it.

A skill that needs a person (confirm a grasp, choose among candidates, click the item on
a camera image) runs ``ask_operator``. The skill publishes a :class:`Prompt` on the run's
operator channel, yields once per tick while it waits, and ends with the answer
(success), a timeout or a declined confirmation (failure) or a cancellation (the prompt
is withdrawn). Who answers is the channel's business: the service's prompt board (the
browser console or the HTTP API), the terminal, or a ``--answers FILE`` script.

The channel is an :class:`OperatorChannel` found in ``ctx.world[OPERATOR_KEY]``; the
executive puts it there. It is polled from the tick thread only; implementations that
take answers from other threads lock themselves.

Events (the run's event log): ``operator_prompt`` (the prompt without its image, plus
``image_size``), ``operator_answer`` (id, answer, source) and ``operator_prompt_closed``
(id, ``reason``: ``timeout``, ``cancelled``, ``declined`` or ``failed``).
"""

from __future__ import annotations

import itertools
import logging
import math
from collections.abc import Generator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

from mmexec.skills.base import (
    FailureKind,
    Output,
    Param,
    SkillCancelled,
    SkillContext,
    SkillFailure,
    skill,
)

__all__ = [
    "KINDS",
    "OPERATOR_KEY",
    "SHAPES",
    "Answer",
    "AnswerError",
    "OperatorChannel",
    "OverlayShape",
    "Prompt",
    "ask_operator",
    "parse_overlay",
    "validate_answer",
]

log = logging.getLogger(__name__)

#: ``ctx.world`` key of the run's :class:`OperatorChannel`.
OPERATOR_KEY = "operator.channel"
#: Prompt kinds: a yes/no question, one of ``options``, a pixel on ``image``.
KINDS = ("confirm", "choose", "point")
#: Overlay shapes drawn on a prompt image (pixel coordinates, origin top left).
SHAPES = ("point", "box", "line", "text")
#: Longest prompt text and option [characters]; most options.
MAX_TEXT = 500
MAX_OPTIONS = 50
#: JPEG quality of a prompt image (0..100).
JPEG_QUALITY = 80

_YES = ("yes", "y", "true", "1")
_NO = ("no", "n", "false", "0")
_ids = itertools.count(1)


class AnswerError(ValueError):
    """An answer that does not fit its prompt (one line, naming where it came from)."""


@dataclass(frozen=True)
class OverlayShape:
    """A shape drawn on a prompt image: ``point`` (one point), ``box`` (two corners),
    ``line`` (two or more points), ``text`` (``label`` at one point); pixels, (u, v) with
    u to the right and v down from the top-left corner."""

    shape: str
    points: tuple[tuple[float, float], ...]
    label: str = ""
    color: str = "#00ff00"

    def to_json(self) -> dict[str, Any]:
        return {"shape": self.shape, "points": [list(p) for p in self.points], "label": self.label,
                "color": self.color}


@dataclass(frozen=True)
class Prompt:
    """One question to the operator.

    ``kind``: one of :data:`KINDS`; ``options``: the choices of ``choose``; ``image``: a
    JPEG (bytes) the question is about, ``image_size`` its (width, height) [px];
    ``overlay``: shapes to draw on it; ``timeout`` [clock s] after ``asked_at`` [clock s]
    (None: waits until answered or cancelled); ``node``: the tree node asking.
    """

    id: str
    kind: str
    text: str
    options: tuple[str, ...] = ()
    image: bytes | None = field(default=None, repr=False)
    image_size: tuple[int, int] | None = None
    overlay: tuple[OverlayShape, ...] = ()
    timeout: float | None = None
    node: str = ""
    asked_at: float = 0.0

    def to_json(self) -> dict[str, Any]:
        """The prompt as plain JSON types, without the image bytes (``has_image`` says
        whether there is one)."""
        return {
            "id": self.id, "kind": self.kind, "text": self.text, "options": list(self.options),
            "has_image": self.image is not None,
            "image_size": list(self.image_size) if self.image_size is not None else None,
            "overlay": [s.to_json() for s in self.overlay], "timeout": self.timeout, "node": self.node,
            "asked_at": self.asked_at,
        }


@dataclass(frozen=True)
class Answer:
    """An operator's answer: ``value`` (bool for confirm, the option for choose, [u, v]
    pixels for point) and its ``source`` (``api``, ``console``, ``terminal``, ``script``)."""

    value: Any
    source: str


class OperatorChannel(Protocol):
    """Where prompts go and answers come from (called from the tick thread)."""

    def ask(self, prompt: Prompt) -> None:
        """Publish ``prompt``; it stays open until :meth:`close`."""

    def poll(self, prompt_id: str, now: float) -> Answer | None:
        """The answer to an open prompt, once there is one (validated with
        :func:`validate_answer`); ``now`` is the clock time [s]. Raises
        :class:`AnswerError` when the answer source cannot answer it properly."""

    def close(self, prompt_id: str, reason: str) -> None:
        """Withdraw the prompt (``answered``, ``timeout``, ``cancelled``, ``declined``,
        ``failed``)."""


def validate_answer(prompt: Prompt, value: Any) -> Any:
    """``value`` converted to the answer type of ``prompt`` (confirm: bool, also
    yes/no/y/n/true/false; choose: one of the options; point: [u, v] finite pixels inside
    the image). Raises :class:`AnswerError` with one line saying what was expected."""
    if prompt.kind == "confirm":
        if isinstance(value, bool):
            return value
        if isinstance(value, str) and value.strip().lower() in _YES + _NO:
            return value.strip().lower() in _YES
        raise AnswerError(f"prompt {prompt.id} (confirm): expected yes or no (true/false), got {value!r}")
    if prompt.kind == "choose":
        if isinstance(value, str) and value in prompt.options:
            return value
        raise AnswerError(f"prompt {prompt.id} (choose): expected one of {list(prompt.options)}, got {value!r}")
    if (not isinstance(value, Sequence) or isinstance(value, str) or len(value) != 2
            or not all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in value)):
        raise AnswerError(f"prompt {prompt.id} (point): expected [u, v], two finite pixel coordinates, got {value!r}")
    u, v = float(value[0]), float(value[1])
    if prompt.image_size is not None:
        w, h = prompt.image_size
        if not (0.0 <= u < w and 0.0 <= v < h):
            raise AnswerError(f"prompt {prompt.id} (point): [{u:g}, {v:g}] is outside the {w}x{h} image")
    return [u, v]


def parse_overlay(raw: Sequence[Any] | None) -> tuple[OverlayShape, ...]:
    """Overlay shapes from a mission's ``overlay`` parameter: a list of mappings
    ``{shape: box, points: [[u0, v0], [u1, v1]], label: ..., color: ...}``. Raises
    ValueError (one line) on a bad entry."""
    out: list[OverlayShape] = []
    for i, item in enumerate(raw or ()):
        where = f"overlay[{i}]"
        if not isinstance(item, Mapping):
            raise ValueError(f"{where}: expected a mapping with 'shape' and 'points', got {item!r}")  # noqa: TRY004
        unknown = sorted(set(item) - {"shape", "points", "label", "color"})
        if unknown:
            raise ValueError(f"{where}: unknown key {unknown[0]!r} (expected shape, points, label, color)")
        shape = item.get("shape")
        if shape not in SHAPES:
            raise ValueError(f"{where}: shape must be one of {list(SHAPES)}, got {shape!r}")
        pts = item.get("points")
        if (not isinstance(pts, Sequence) or isinstance(pts, str)
                or not all(isinstance(p, Sequence) and not isinstance(p, str) and len(p) == 2
                           and all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
                                   for x in p) for p in pts)):
            raise ValueError(f"{where}: points must be a list of [u, v] pixel pairs, got {pts!r}")
        need = {"point": 1, "text": 1, "box": 2}.get(shape)
        if (need is not None and len(pts) != need) or (shape == "line" and len(pts) < 2):
            raise ValueError(f"{where}: a {shape} takes {need if need else 'two or more'} point(s), got {len(pts)}")
        out.append(OverlayShape(shape, tuple((float(p[0]), float(p[1])) for p in pts),
                                str(item.get("label", "")), str(item.get("color", "#00ff00"))))
    return tuple(out)


def _camera_jpeg(ctx: SkillContext) -> tuple[bytes, tuple[int, int]]:
    """The current camera frame as a JPEG and its (width, height); SkillFailure when
    there is no camera or no frame."""
    camera = ctx.robot.camera
    if camera is None:
        raise SkillFailure(FailureKind.PRECONDITION, "ask_operator: image 'camera' needs a camera, and this robot has none")
    frame = camera.frame()
    if frame is None:
        raise SkillFailure(FailureKind.EXECUTION, "ask_operator: the camera has no frame to show")
    import cv2

    ok, buf = cv2.imencode(".jpg", frame.rgb[:, :, ::-1], [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    if not ok:
        raise SkillFailure(FailureKind.EXECUTION, "ask_operator: the camera frame could not be encoded as JPEG")
    h, w = frame.rgb.shape[:2]
    return bytes(buf), (int(w), int(h))


def _build_prompt(ctx: SkillContext, kind: str, text: str, options: list[Any] | None, image: str,
                  overlay: list[Any] | None, timeout: float | None) -> Prompt:
    def bad(msg: str) -> SkillFailure:
        return SkillFailure(FailureKind.PRECONDITION, f"ask_operator: {msg}")

    if not text.strip() or len(text) > MAX_TEXT:
        raise bad(f"text must be 1..{MAX_TEXT} characters, got {len(text.strip())}")
    opts = tuple(str(o) for o in options or ())
    if kind == "choose" and not 1 <= len(opts) <= MAX_OPTIONS:
        raise bad(f"a choose prompt needs 1..{MAX_OPTIONS} options, got {len(opts)}")
    if kind != "choose" and opts:
        raise bad(f"options are for choose prompts, not {kind}")
    if len(set(opts)) != len(opts):
        raise bad(f"options must be distinct, got {list(opts)}")
    if timeout is not None and not (math.isfinite(timeout) and timeout > 0):
        raise bad(f"timeout must be a finite number of seconds > 0, got {timeout!r}")
    if kind == "point" and image == "none":
        raise bad("a point prompt needs an image (image: camera)")
    try:
        shapes = parse_overlay(overlay)
    except ValueError as e:
        raise bad(str(e)) from None
    if shapes and image == "none":
        raise bad("an overlay needs an image (image: camera)")
    jpeg, size = _camera_jpeg(ctx) if image == "camera" else (None, None)
    return Prompt(id=f"p{next(_ids)}", kind=kind, text=text, options=opts, image=jpeg, image_size=size,
                  overlay=shapes, timeout=timeout, node=ctx.node_path, asked_at=ctx.clock.now())


@skill(
    "ask_operator",
    params=[
        Param("kind", str, required=True, choices=KINDS, doc="confirm (yes/no), choose (one of options), point (a pixel)"),
        Param("text", str, required=True, doc="the question, as the operator reads it"),
        Param("options", list, doc="choose: the options (strings)"),
        Param("image", str, default="none", choices=("none", "camera"),
              doc="'camera': show the current camera frame (needed by point)"),
        Param("overlay", list, doc="shapes drawn on the image: [{shape, points, label, color}]"),
        Param("timeout", float, unit="s", doc="fail when no answer came within this clock time"),
        Param("decline_fails", bool, default=True, doc="confirm: a 'no' fails the skill (else answer false)"),
    ],
    outputs=[
        Output("answer", object, doc="true/false (confirm), the option (choose), [u, v] px (point)"),
        Output("source", str, doc="who answered: api, console, terminal, script"),
    ],
)
def ask_operator(ctx: SkillContext, kind: str, text: str, options: list[Any] | None = None, image: str = "none",
                 overlay: list[Any] | None = None, timeout: float | None = None,
                 decline_fails: bool = True) -> Generator[None, None, dict[str, Any]]:
    """Ask the operator and wait (yielding) for the answer. Fails with TIMEOUT when none
    came within ``timeout`` clock seconds, EXECUTION when a confirmation is declined
    (``decline_fails``), PRECONDITION when nobody can answer (no operator channel) or the
    answer source cannot answer this prompt (a script's answer of the wrong kind)."""
    channel: OperatorChannel | None = ctx.world.get(OPERATOR_KEY)
    if channel is None:
        raise SkillFailure(FailureKind.PRECONDITION,
                           "ask_operator: nobody can answer: run under 'mmexec serve', on a terminal, "
                           "or give 'mmexec run --answers FILE'")
    prompt = _build_prompt(ctx, kind, text, options, image, overlay, timeout)
    channel.ask(prompt)
    ctx.emit("operator_prompt", node=ctx.node_path, **{k: v for k, v in prompt.to_json().items() if k != "node"})
    deadline = None if timeout is None else prompt.asked_at + timeout
    closed = "cancelled"
    try:
        while True:
            now = ctx.clock.now()
            try:
                answer = channel.poll(prompt.id, now)
            except AnswerError as e:
                closed = "failed"
                raise SkillFailure(FailureKind.PRECONDITION, f"ask_operator: {e}") from None
            if answer is not None:
                break
            if deadline is not None and now >= deadline:
                closed = "timeout"
                raise SkillFailure(FailureKind.TIMEOUT,
                                   f"ask_operator: no answer to {text!r} within {timeout:g} s")
            yield
        ctx.emit("operator_answer", node=ctx.node_path, id=prompt.id, answer=answer.value, source=answer.source)
        if kind == "confirm" and decline_fails and answer.value is False:
            closed = "declined"
            raise SkillFailure(FailureKind.EXECUTION, f"ask_operator: the operator declined: {text!r}")
        closed = "answered"
        return {"answer": answer.value, "source": answer.source}
    except SkillCancelled:
        closed = "cancelled"
        raise
    finally:
        channel.close(prompt.id, closed)
        if closed != "answered":
            ctx.emit("operator_prompt_closed", node=ctx.node_path, id=prompt.id, reason=closed)
        log.debug("prompt %s closed: %s", prompt.id, closed)
