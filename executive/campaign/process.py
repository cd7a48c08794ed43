"""One trial as one ``mmexec run`` subprocess (:func:`run_trial`), in its own session so
that an interrupt reaches its whole process group, with an optional wall-time limit.
It runs inside a pool worker or a Ray task (:mod:`mmexec.executive.campaign.pools`)."""

from __future__ import annotations

import logging
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from mmexec.executive.campaign.trial import TrialResult, TrialSpec, parse_trial_log

__all__ = ["STOP_GRACE", "run_trial"]

log = logging.getLogger(__name__)

#: The Python snippet each trial process runs (the ``mmexec`` entry point).
_ENTRY = "import sys; from mmexec.executive.cli import main; sys.exit(main())"


def _tail(path: str, lines: int = 3) -> str:
    try:
        text = Path(path).read_text(errors="replace")
    except OSError as e:
        return f"<no output: {e.strerror}>"
    kept = [ln for ln in text.splitlines() if ln.strip()]
    return " | ".join(kept[-lines:])


#: Wall seconds an interrupted trial gets to stop before it is killed.
STOP_GRACE = 10.0


def _stop_trial(proc: subprocess.Popen[bytes]) -> None:
    """SIGINT the trial's process group, wait up to :data:`STOP_GRACE`, then SIGKILL it."""
    try:
        os.killpg(proc.pid, signal.SIGINT)
        proc.wait(timeout=STOP_GRACE)
    except subprocess.TimeoutExpired:
        log.warning("trial process %d still running %g s after SIGINT; killing it", proc.pid, STOP_GRACE)
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    except ProcessLookupError:
        log.debug("trial process %d already gone", proc.pid)


def run_trial(spec: TrialSpec) -> TrialResult:
    """Run one trial as a ``mmexec run`` subprocess (in a pool worker or a Ray task) and
    parse its event log. Never raises for what the trial does: a crash, a kill or a
    wall-time overrun is an ``error`` result; exit code 2 (bad input) is an ``error``
    whose reason holds the trial's own error lines."""
    Path(spec.log_path).parent.mkdir(parents=True, exist_ok=True)
    cmd = [sys.executable, "-c", _ENTRY, *spec.argv]
    t0 = time.monotonic()
    note = ""
    with open(spec.out_path, "wb") as out:
        proc = subprocess.Popen(cmd, cwd=spec.cwd, stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                start_new_session=True)
        try:
            rc: int | None = proc.wait(timeout=spec.wall_limit)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
            rc = proc.returncode
            note = f"killed after {spec.wall_limit:g} s of wall time (--trial-timeout)"
        except BaseException:
            # Ctrl-C (or a cancelled Ray task): the trial runs in its own session, so pass
            # the interrupt on; `mmexec run` halts its tree, leaves the robot safe and
            # writes run_end (interrupted). Past the grace period it is killed.
            _stop_trial(proc)
            raise
    wall = time.monotonic() - t0
    if not note and rc == 2:
        note = f"bad input: {_tail(spec.out_path, 5)}"
    elif not note and rc is not None and rc > 1:
        note = f"trial process exited with code {rc}: {_tail(spec.out_path)}"
    return parse_trial_log(spec, exit_code=rc, wall=wall, note=note)
