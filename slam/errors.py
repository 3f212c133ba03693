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
    "OutputError",
]


class LogFormatError(InputError):
    """A log, trajectory or relations file is malformed; the message names file and line."""


class DatasetError(LineslamError):
    """A registered dataset is unknown, missing, or fails its checksum."""


class EstimationError(LineslamError):
    """An estimator could not produce a result (e.g. an indeterminate system)."""


class EvaluationError(LineslamError):
    """An evaluation cannot be trusted (e.g. too many relation timestamps not in the trajectory)."""


class OutputError(LineslamError):
    """A results path cannot be written: it is the input, not a folder, read-only, full, ...

    Parameters
    ----------
    path
        The path that cannot be written.
    message
        Why, in one line.
    """

    def __init__(self, path: str, message: str) -> None:
        self.path = path
        self.reason = message
        super().__init__(f"{path}: {message}")
