"""Whitespace-separated numeric tables (TUM, relations) with line-numbered errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from slam.errors import LogFormatError
from slam.io._text import iter_text_lines

__all__ = ["read_numeric_table"]


def read_numeric_table(
    path: str | Path, n_fields: int, what: str
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Rows of ``n_fields`` finite numbers; ``#`` lines and blank lines are skipped.

    Returns
    -------
    values : ndarray, shape (m, n_fields)
    line_numbers : ndarray, shape (m,)
        1-based line number of each row, for messages.

    Raises
    ------
    LogFormatError
        A row with another field count, a field that is not a number, NaN or infinity, an
        empty or binary file, or a file with no rows; file and line are named.
    """
    rows: list[list[str]] = []
    numbers: list[int] = []
    for line_number, line in iter_text_lines(path):
        tokens = line.split()
        if not tokens or tokens[0].startswith("#"):
            continue
        if len(tokens) != n_fields:
            raise LogFormatError(
                f"{what}: {len(tokens)} fields, expected {n_fields}", str(path), line_number
            )
        rows.append(tokens)
        numbers.append(line_number)
    if not rows:
        raise LogFormatError(f"no {what} rows in the file", str(path))
    try:
        values = np.array(rows, dtype=np.float64)
    except ValueError:
        for tokens, line_number in zip(rows, numbers, strict=True):
            for token in tokens:
                try:
                    float(token)
                except ValueError:
                    raise LogFormatError(
                        f"{what}: {token!r} is not a number", str(path), line_number
                    ) from None
        raise  # pragma: no cover - np.array failed where float() did not
    finite = np.isfinite(values).all(axis=1)
    if not finite.all():
        i = int(np.flatnonzero(~finite)[0])
        raise LogFormatError(f"{what}: NaN or infinite value", str(path), int(numbers[i]))
    return values, np.asarray(numbers, dtype=np.int64)
