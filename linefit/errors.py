"""The project's one exception hierarchy.

Every error raised on purpose by ``linefit`` or ``slam`` derives from :class:`LineslamError`,
so user code can catch the whole family with one ``except``.  ``slam.errors`` re-exports these
classes and adds the ones that only make sense across poses (log formats, datasets).

``linefit`` is the lowest layer, so the root of the hierarchy lives here.
"""

from __future__ import annotations

__all__ = [
    "ConfigError",
    "DegenerateGeometryError",
    "InputError",
    "LineslamError",
]


class LineslamError(Exception):
    """Root of every error raised on purpose by lineslam."""


class ConfigError(LineslamError, ValueError):
    """A configuration value is out of range, of the wrong type, or unknown."""


class InputError(LineslamError, ValueError):
    """Input data are malformed (wrong shape, NaN where a number is needed, wrong file type).

    Parameters
    ----------
    message
        What is wrong, in one line.
    path
        The file the bad input came from, if any.
    line_number
        1-based line number inside ``path``, if known.
    """

    def __init__(self, message: str, path: str | None = None, line_number: int | None = None):
        self.path = path
        self.line_number = line_number
        self.reason = message
        where = ""
        if path is not None:
            where = f"{path}:{line_number}: " if line_number is not None else f"{path}: "
        super().__init__(where + message)


class DegenerateGeometryError(LineslamError, ValueError):
    """The geometry does not determine the requested quantity.

    Examples: fewer than two distinct points, all points on a ray through the sensor,
    a singular covariance where an inverse is needed.
    """
