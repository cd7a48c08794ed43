"""Plain data for the campaign's own files: YAML-loaded values as plain dicts and lists,
and JSON files written whole (a reader never sees half a file)."""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

__all__ = ["plain", "write_json"]


def plain(value: Any) -> Any:
    """YDict/YList (and tuples) as plain dicts and lists, for JSON and YAML output."""
    if isinstance(value, Mapping):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    return value


def write_json(path: Path, data: Any) -> None:
    """Write ``data`` as indented JSON with sorted keys: to ``PATH.tmp``, then renamed
    over ``path``."""
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(json.dumps(data, indent=2, sort_keys=True) + "\n")
    os.replace(tmp, path)
