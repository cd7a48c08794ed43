"""Validation helpers shared by the navigation layers' frozen configs: each returns the
problems it finds as ``"name: must be > 0, got X"`` lines (no exceptions), so a config's
``validate()`` can list every problem at once."""

from __future__ import annotations

from typing import Any, Protocol, TypeVar

__all__ = ["checked", "non_negative", "positive"]


def positive(cfg: Any, *names: str) -> list[str]:
    """A line for each attribute of ``cfg`` in ``names`` that is not > 0 (nan included)."""
    return [f"{n}: must be > 0, got {getattr(cfg, n)}" for n in names if not getattr(cfg, n) > 0]


def non_negative(cfg: Any, *names: str) -> list[str]:
    """A line for each attribute of ``cfg`` in ``names`` that is not >= 0 (nan included)."""
    return [f"{n}: must be >= 0, got {getattr(cfg, n)}" for n in names if not getattr(cfg, n) >= 0]


class _Validating(Protocol):
    def validate(self) -> list[str]: ...


C = TypeVar("C", bound=_Validating)


def checked(config: C) -> C:
    """``config`` itself when its ``validate()`` finds nothing; otherwise a ValueError
    naming the config type and listing every problem."""
    errs = config.validate()
    if errs:
        raise ValueError(f"{type(config).__name__}: " + "; ".join(errs))
    return config
