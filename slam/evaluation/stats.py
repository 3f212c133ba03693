"""Summary statistics of error samples, as evo reports them."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["ErrorStats"]


@dataclass(frozen=True)
class ErrorStats:
    """RMSE, mean, median, standard deviation (population, as evo), min, max of errors."""

    n: int
    rmse: float
    mean: float
    median: float
    std: float
    min: float
    max: float

    @classmethod
    def of(cls, errors: NDArray[np.float64]) -> ErrorStats:
        """Statistics of a 1-D array of non-negative errors (NaN everywhere if empty)."""
        e = np.asarray(errors, dtype=np.float64)
        if e.size == 0:
            nan = math.nan
            return cls(0, nan, nan, nan, nan, nan, nan)
        return cls(
            n=int(e.size),
            rmse=float(np.sqrt(np.mean(e**2))),
            mean=float(np.mean(e)),
            median=float(np.median(e)),
            std=float(np.std(e)),
            min=float(np.min(e)),
            max=float(np.max(e)),
        )

    def to_dict(self) -> dict[str, float]:
        """JSON-ready copy."""
        return asdict(self)
