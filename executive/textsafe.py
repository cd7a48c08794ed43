"""Make user-supplied text safe to print on a terminal.

Text from missions, requests, configs, skill reports and event logs reaches the user's
terminal: the live status line, ``report`` messages, error lines, ``mmexec log``
output. A control character in it (ESC starting an ANSI sequence that clears the
screen, retitles the window, moves the cursor or fakes a hyperlink; a carriage return
overwriting the line; a bidirectional override reordering it) would act on the terminal
instead of being seen. :func:`printable` shows each such character as a visible escape
(``\\x1b``, ``\\r``, ``\\u202e``), the way ``repr`` does, and leaves all other text,
including non-ASCII letters, unchanged.
"""

from __future__ import annotations

import re

__all__ = ["printable"]

# C0 controls (but tab and newline, handled below), DEL, C1 controls (0x9b is a one-byte
# CSI), and the Unicode bidirectional embeddings, overrides and isolates.
_UNSAFE = re.compile("[\x00-\x08\x0b-\x1f\x7f-\x9f\u061c\u200e\u200f\u202a-\u202e\u2066-\u2069]")
_UNSAFE_LINE = re.compile("[\x00-\x1f\x7f-\x9f\u061c\u200e\u200f\u202a-\u202e\u2066-\u2069]")
_NAMED = {"\t": "\\t", "\n": "\\n", "\r": "\\r"}


def _escape(m: re.Match[str]) -> str:
    ch = m.group(0)
    named = _NAMED.get(ch)
    if named is not None:
        return named
    code = ord(ch)
    return f"\\x{code:02x}" if code <= 0xFF else f"\\u{code:04x}"


def printable(text: object, *, multiline: bool = False) -> str:
    """``str(text)`` with every terminal control character shown as an escape.

    One line by default: newlines and tabs are escaped too, so a message cannot forge a
    second output line. ``multiline=True`` keeps newlines and tabs (for a rendered
    summary or tree that is several lines on purpose).
    """
    s = str(text)
    return (_UNSAFE if multiline else _UNSAFE_LINE).sub(_escape, s)
