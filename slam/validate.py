"""Validation helpers: configuration values (:class:`ConfigError`) and public-API arguments.

The estimators' constructors check their configuration arguments with :func:`check_config`
(their ``add_scan`` uses :func:`slam.types.check_scan` and :func:`slam.types.check_lines`), so
that misuse raises the package's own error naming the argument instead of an
``AttributeError`` from deep inside.
"""

from __future__ import annotations

import math
from typing import TypeVar

from slam.errors import ConfigError

__all__ = ["check_config", "nonneg", "positive", "require"]

T = TypeVar("T")


def require(ok: bool, message: str) -> None:
    """Raise :class:`ConfigError` with ``message`` unless ``ok``."""
    if not ok:
        raise ConfigError(message)


def nonneg(name: str, value: float) -> None:
    """``value`` must be a finite number >= 0."""
    require(math.isfinite(value) and value >= 0.0, f"{name} must be a finite number >= 0")


def positive(name: str, value: float) -> None:
    """``value`` must be a finite number > 0."""
    require(math.isfinite(value) and value > 0.0, f"{name} must be a finite number > 0")


def check_config(value: object, kind: type[T], name: str) -> T:
    """``value`` if it is a ``kind`` (or None → ``kind()``), else :class:`ConfigError`.

    Parameters
    ----------
    value
        The argument (e.g. ``config=`` of a constructor).
    kind
        The configuration class it must be.
    name
        The argument's name, for the message.
    """
    if value is None:
        return kind()
    if not isinstance(value, kind):
        article = "an" if kind.__name__[:1] in "AEIOU" else "a"
        raise ConfigError(f"{name} must be {article} {kind.__name__}, got {type(value).__name__}")
    return value
