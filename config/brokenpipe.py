"""Standard output closed by its reader (``mmexec show ... | head``), for every command line.

Python ignores SIGPIPE, so a write to a pipe whose reader has gone raises
:class:`BrokenPipeError`; the commands (``mmexec``, ``python -m mmexec.sim.mapgen``)
catch it at their top level and return :func:`detach_stdout`'s code. Dying by SIGPIPE
instead (``signal.SIG_DFL``) is not an option for a process that may be driving a robot:
it would skip the safe stop.
"""

from __future__ import annotations

import os
import sys

__all__ = ["EXIT_BROKEN_PIPE", "detach_stdout"]

#: The exit code: 128 + SIGPIPE, what a Unix tool killed by SIGPIPE reports to its shell.
EXIT_BROKEN_PIPE = 141


def detach_stdout() -> int:
    """Point file descriptor 1 at /dev/null, so the interpreter's last flush of what is
    still buffered cannot fail again (Python's "Exception ignored ... BrokenPipeError"),
    and return :data:`EXIT_BROKEN_PIPE`. Prints nothing: the user closed the pipe on
    purpose."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, sys.stdout.fileno())
    finally:
        os.close(devnull)
    return EXIT_BROKEN_PIPE
