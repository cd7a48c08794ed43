"""The ``serve:`` section of a run config: how ``mmexec serve`` exposes the executive.

```yaml
serve:
  token_file: secrets/console.token   # relative to the config file; default: a token made at start
  cors_origins: []                    # browser origins allowed to call the API (default: none)
  max_body: 65536                     # bytes a request body may have (413 beyond)
  max_queue: 1000                     # requests waiting at most (429 beyond)
  history: 100                        # finished requests kept for GET /api/requests
  pose_hz: 10                         # wall-clock rates of the WebSocket streams [Hz]
  scan_hz: 5
  camera_hz: 2
```
"""

from __future__ import annotations

import math
import os
import secrets
import stat
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mmexec.config.yamlload import InputError, Mark, Problems, YDict, bind

__all__ = ["MIN_TOKEN_CHARS", "ServeSettings", "load_token", "parse_section"]

#: A token read from a file must be at least this long (characters).
MIN_TOKEN_CHARS = 16
_MAX_TOKEN_FILE = 4096


@dataclass(frozen=True)
class ServeSettings:
    """``serve:`` (see the module doc). Rates are wall-clock Hz; sizes are bytes."""

    token_file: str | None = None
    cors_origins: list[str] = field(default_factory=list)
    max_body: int = 65536
    max_queue: int = 1000
    history: int = 100
    pose_hz: float = 10.0
    scan_hz: float = 5.0
    camera_hz: float = 2.0

    def validate(self) -> list[str]:
        out = []
        if not 1024 <= self.max_body <= 16 * 1024 * 1024:
            out.append(f"max_body: expected 1024..16777216 bytes, got {self.max_body}")
        if not 1 <= self.max_queue <= 100_000:
            out.append(f"max_queue: expected 1..100000 requests, got {self.max_queue}")
        if not 0 <= self.history <= 100_000:
            out.append(f"history: expected 0..100000 requests, got {self.history}")
        for name in ("pose_hz", "scan_hz", "camera_hz"):
            hz = getattr(self, name)
            if not (math.isfinite(hz) and 0.0 < hz <= 100.0):
                out.append(f"{name}: expected a rate in (0, 100] Hz, got {hz:g}")
        for origin in self.cors_origins:
            if origin == "*" or not origin.startswith(("http://", "https://")):
                out.append(f"cors_origins: expected origins like 'http://host:port' (no '*'), got {origin!r}")
        return out


def parse_section(section: Any, mark: Mark) -> ServeSettings:
    """Bind a config's ``serve:`` section (None: the defaults). Raises InputError."""
    if section is None:
        return ServeSettings()
    problems = Problems()
    where = getattr(section, "mark", mark)
    if not isinstance(section, YDict):
        raise InputError.at(where, f"serve: expected a mapping of serve settings, got {section!r}")
    settings = bind(ServeSettings, section, where, "serve", problems)
    problems.raise_if_any()
    assert isinstance(settings, ServeSettings)
    return settings


def load_token(settings: ServeSettings, config_path: Path, mark: Mark) -> tuple[str, bool]:
    """The API token and whether it came from the file: ``token_file`` (relative to the
    config file; a regular file of at most 4 KiB not readable by others, whose first line
    is the token, at least :data:`MIN_TOKEN_CHARS` characters), else a new random one.
    Raises InputError located at ``token_file``."""
    if settings.token_file is None:
        return secrets.token_urlsafe(24), False
    path = config_path.parent / settings.token_file
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError as e:
        raise InputError.at(mark, f"serve.token_file: {path}: cannot open: {e.strerror or e}") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode) or st.st_size > _MAX_TOKEN_FILE:
            raise InputError.at(mark, f"serve.token_file: {path}: expected a regular file of at most "
                                      f"{_MAX_TOKEN_FILE} bytes")
        if st.st_mode & 0o077:
            raise InputError.at(mark, f"serve.token_file: {path}: readable by others (mode "
                                      f"{stat.S_IMODE(st.st_mode):o}); chmod 600 it")
        data = os.read(fd, _MAX_TOKEN_FILE + 1)
    finally:
        os.close(fd)
    lines = data.decode("utf-8", errors="replace").splitlines()
    token = lines[0].strip() if lines else ""
    if len(token) < MIN_TOKEN_CHARS or not token.isprintable() or " " in token:
        raise InputError.at(mark, f"serve.token_file: {path}: the first line must be a token of at least "
                                  f"{MIN_TOKEN_CHARS} printable characters without spaces")
    return token, True
