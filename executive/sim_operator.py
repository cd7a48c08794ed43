"""A scripted operator for the simulator: clicks the dangerous part of the object a prompt
shows, from the sim's ground truth plus pixel noise (tests and campaigns of the
fetch_object mission's dangerous items, docs/fetch_object.md).

``mmexec run --answers FILE`` (and ``mmexec campaign --answers FILE``) takes, besides the
usual list of answers (:mod:`mmexec.executive.serve.prompts`), a file holding one mapping::

    sim_click: {noise_px: 3.0, after: 2.0, part: dangerous}

Each ``point`` prompt is then answered ``after`` clock seconds with the pixel where the
true centre of the ``part`` (``dangerous``: the part sim/objects.py marks dangerous, or a
part's name) of the object inside the prompt's ``box`` overlay appears in the camera now
(the prompt's image is the current frame), plus Gaussian noise of ``noise_px`` pixels per
axis drawn from the run's seed. The object is the untagged object whose true centre
projects inside the box (the nearest to the box centre when several do). A prompt that is
not a point prompt, has no box, or shows no object with that part is answered with a
failure of the skill (:class:`~mmexec.skills.operator.AnswerError`), so a scripted run
never waits for a person. SIM-ONLY: the truth comes from the pybullet world.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mmexec.config.yamlload import Mark, Problems, YDict, bind, load_yaml
from mmexec.skills.operator import Answer, AnswerError, Prompt

__all__ = ["SimClick", "SimClickOperator", "sim_click_operator"]


@dataclass(frozen=True)
class SimClick:
    """``sim_click:`` settings: pixel ``noise_px`` (std per axis), ``after`` [clock s]
    before answering, which ``part`` is clicked."""

    noise_px: float = 3.0
    after: float = 1.0
    part: str = "dangerous"

    def validate(self) -> list[str]:
        out = []
        if not (math.isfinite(self.noise_px) and self.noise_px >= 0):
            out.append(f"noise_px: expected pixels >= 0, got {self.noise_px}")
        if not (math.isfinite(self.after) and self.after >= 0):
            out.append(f"after: expected clock seconds >= 0, got {self.after}")
        return out


@dataclass(frozen=True)
class _SimClickFile:
    sim_click: SimClick


class SimClickOperator:
    """The scripted sim operator (module doc); an :class:`~mmexec.skills.operator.OperatorChannel`."""

    source = "script"

    def __init__(self, robot: Callable[[], Any], settings: SimClick, seed: int | None, path: str) -> None:
        self.robot = robot  # the run's robot, once built
        self.settings = settings
        self.path = path
        self.rng = np.random.default_rng(None if seed is None else [seed, 7715])
        self._pending: dict[str, tuple[Prompt, list[float] | str]] = {}
        #: every click made: (prompt id, object, true pixel, clicked pixel)
        self.clicks: list[tuple[str, str, tuple[float, float], tuple[float, float]]] = []

    def _click(self, prompt: Prompt) -> list[float] | str:
        """The noisy pixel of the part, or why there is none."""
        from mmexec.sim.objects import object_frame, part_centre, project_point

        if prompt.kind != "point":
            return f"{self.path}: sim_click answers point prompts only, prompt {prompt.id} is a {prompt.kind}"
        box = next((s for s in prompt.overlay if s.shape == "box"), None)
        if box is None:
            return f"{self.path}: prompt {prompt.id} shows no box to click in"
        (x0, y0), (x1, y1) = box.points
        r = self.robot()
        if not hasattr(r, "scene_handles") or not hasattr(r, "world"):
            return f"{self.path}: sim_click needs the simulator (backend: sim)"
        cam = r.camera
        K = cam.intrinsics
        T_opt = r.core.base_T() @ cam.pose_in_base()
        best: tuple[float, str, tuple[float, float]] | None = None
        for obj in r.world.spec.objects:
            kind = obj.model
            parts = [p for p in kind.parts if (p.dangerous if self.settings.part == "dangerous" else p.name == self.settings.part)]
            if not parts:
                continue
            T = object_frame(r.cid, r.scene_handles.items[obj.name], kind)
            centre = project_point(T_opt, K.fx, K.fy, K.cx, K.cy, T[:3, 3])
            if centre is None or not (x0 <= centre[0] <= x1 and y0 <= centre[1] <= y1):
                continue
            pc = (T @ np.array([*part_centre(kind, parts[0].name), 1.0]))[:3]
            px = project_point(T_opt, K.fx, K.fy, K.cx, K.cy, pc)
            if px is None:
                continue
            d = math.hypot(centre[0] - (x0 + x1) / 2, centre[1] - (y0 + y1) / 2)
            if best is None or d < best[0]:
                best = (d, obj.name, px)
        if best is None:
            return f"{self.path}: no object with a {self.settings.part} part inside the box of prompt {prompt.id}"
        _, name, (u, v) = best
        n = self.settings.noise_px
        du, dv = (self.rng.normal(0.0, n, 2) if n > 0 else (0.0, 0.0))
        W, H = prompt.image_size or (K.width, K.height)
        cu, cv = float(min(max(u + du, 0.0), W - 1.0)), float(min(max(v + dv, 0.0), H - 1.0))
        self.clicks.append((prompt.id, name, (u, v), (cu, cv)))
        return [cu, cv]

    def ask(self, prompt: Prompt) -> None:
        self._pending[prompt.id] = (prompt, self._click(prompt))

    def poll(self, prompt_id: str, now: float) -> Answer | None:
        prompt, click = self._pending[prompt_id]
        if isinstance(click, str):
            raise AnswerError(click)
        if now < prompt.asked_at + self.settings.after:
            return None
        return Answer(click, self.source)

    def close(self, prompt_id: str, reason: str) -> None:
        self._pending.pop(prompt_id, None)


def sim_click_operator(path: str | Path, robot: Callable[[], Any], seed: int | None) -> SimClickOperator | None:
    """The scripted sim operator when the answers file ``path`` holds a ``sim_click:``
    mapping (None for any other file: a list of answers); ``robot()`` gives the run's
    robot once built. Raises InputError (located) on a bad ``sim_click`` section."""
    raw = load_yaml(path)
    if not (isinstance(raw, YDict) and "sim_click" in raw):
        return None
    problems = Problems()
    bound = bind(_SimClickFile, raw, getattr(raw, "mark", Mark(str(path), 1, 1)), "", problems)
    problems.raise_if_any()
    assert isinstance(bound, _SimClickFile)
    return SimClickOperator(robot, bound.sim_click, seed, str(path))
