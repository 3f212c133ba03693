"""Validation helpers shared by the configuration dataclasses (raise :class:`ConfigError`)."""

from __future__ import annotations

import math

from slam.errors import ConfigError

__all__ = ["nonneg", "positive", "require"]


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
