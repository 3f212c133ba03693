"""Errors of the ``slam`` package: the ``linefit`` hierarchy plus what only ``slam`` raises."""

from __future__ import annotations

from linefit.errors import ConfigError, DegenerateGeometryError, InputError, LineslamError

__all__ = [
    "ConfigError",
    "DatasetError",
    "DegenerateGeometryError",
    "EstimationError",
    "EvaluationError",
    "InputError",
    "LineslamError",
    "LogFormatError",
]


class LogFormatError(InputError):
    """A log, trajectory or relations file is malformed; the message names file and line."""


class DatasetError(LineslamError):
    """A registered dataset is unknown, missing, or fails its checksum."""


class EstimationError(LineslamError):
    """An estimator could not produce a result (e.g. an indeterminate system)."""


class EvaluationError(LineslamError):
    """An evaluation cannot be trusted (e.g. too many relation timestamps not in the trajectory)."""
