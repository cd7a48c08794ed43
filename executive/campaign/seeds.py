"""Trial seeds: trial ``i`` of a campaign with seed ``S`` runs with
``trial_seed(S, i)``, the first four bytes, big-endian, of
``sha256("mmexec-campaign:S:i")`` (docs/campaigns.md). Hashing, rather than ``S + i``,
keeps the trials of campaigns with neighbouring seeds apart; the formula needs neither
Python's nor numpy's random generators, so it is stable across their versions and
computable by hand."""

from __future__ import annotations

import hashlib

__all__ = ["trial_seed"]


def trial_seed(seed: int, index: int) -> int:
    """Seed of trial ``index`` (0-based) of a campaign with seed ``seed``: the first four
    bytes, big-endian, of ``sha256(f"mmexec-campaign:{seed}:{index}")``, in [0, 2**32)."""
    digest = hashlib.sha256(f"mmexec-campaign:{seed}:{index}".encode()).digest()
    return int.from_bytes(digest[:4], "big")
