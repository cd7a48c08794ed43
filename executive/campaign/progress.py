"""The campaign's progress output: one redrawn line on a terminal, one plain line per
finished trial otherwise (docs/campaigns.md, "Progress")."""

from __future__ import annotations

import time
from typing import TextIO

from mmexec.executive.campaign.trial import TrialResult
from mmexec.executive.runner import Progress

__all__ = ["CampaignProgress", "hms"]


class CampaignProgress:
    """Trials done, successes so far and an ETA: one redrawn line on a terminal, a plain
    line per finished trial otherwise."""

    def __init__(self, stream: TextIO, *, total: int, done: list[TrialResult], enabled: bool | None) -> None:
        self.stream = stream
        self.total = total
        self.results = list(done)
        self.start_done = len(done)
        self.t0 = time.monotonic()
        self.tty = stream.isatty() if enabled is None else enabled
        self.line = Progress(stream, enabled=self.tty, interval=0.0)

    def _status(self) -> str:
        n = len(self.results)
        ok = sum(r.outcome == "success" for r in self.results)
        errors = sum(r.outcome == "error" for r in self.results)
        elapsed = time.monotonic() - self.t0
        ran = n - self.start_done
        eta = "-" if ran == 0 else hms(elapsed / ran * (self.total - n))
        rate = f"{100.0 * ok / n:.1f}%" if n else "-"
        return (f"[{n}/{self.total}] {ok} ok ({rate})" + (f", {errors} errors" if errors else "")
                + f", elapsed {hms(elapsed)}, ETA {eta}")

    def add(self, r: TrialResult) -> None:
        self.results.append(r)
        if self.tty:
            self.line.update(self._status(), force=True)
        else:
            why = f": {r.reason}" if r.reason else ""
            self.stream.write(f"trial {r.index:04d} seed {r.seed}: {r.outcome}, {r.clock:.1f} s clock, "
                              f"{r.wall:.1f} s wall{why}  {self._status()}\n")
            self.stream.flush()

    def finish(self) -> None:
        self.line.clear()


def hms(seconds: float) -> str:
    s = round(seconds)
    h, rem = divmod(s, 3600)
    m, s = divmod(rem, 60)
    return f"{h}h{m:02d}m" if h else (f"{m}m{s:02d}s" if m else f"{s}s")
