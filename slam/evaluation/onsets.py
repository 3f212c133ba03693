"""Where a run's error entered: the times that its relations with large errors span.

A trajectory that is right but for one wrong step at time ``τ`` (a wrong loop closure, a slip
the front end missed, a jump of the laser odometry) errs, by about that step, on exactly the
relations that span ``τ`` (``t1 ≤ τ < t2``, either order of the two stamps) and on no other.
So the *onset* of an error is the time spanned by the most relations whose error exceeds a
threshold (*bad*) and by the fewest others (*good*; those show that the step at ``τ`` was
right, or was undone before their second stamp).  :func:`error_onsets` finds them greedily:
the time with the largest ``bad − good`` among the relations spanning it, its bad relations
counted as explained, then the next, while a time explains at least ``min_relations`` bad
relations more than the good ones it spans.  An error that a later step undoes (a closure
that takes the wrong step back) gives two onsets: the relations spanning only the fix err
the other way.

The balance only changes at a relation's stamp, so each onset is an interval between
relation stamps (``from_s``, ``until_s``: the consecutive stamps over which the balance stays
at its largest): the step happened there, as far as the relations can tell.
``python scripts/error_onsets.py RUN --log NAME`` prints a run's onsets with the loop closures
accepted near each.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slam.errors import EvaluationError

__all__ = ["ErrorOnset", "error_onsets"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class ErrorOnset:
    """One time where a run's error entered (:func:`error_onsets`).

    Attributes
    ----------
    from_s, until_s : float
        The interval between relation stamps in which the step lies (s, the relations'
        clock).
    bad, good : int
        Relations spanning it with error above the threshold (not explained by an earlier
        onset) and at or below it.
    mean_error_m : float
        Mean translation error of those bad relations (m).
    """

    from_s: float
    until_s: float
    bad: int
    good: int
    mean_error_m: float

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready fields."""
        return {
            "from_s": self.from_s,
            "until_s": self.until_s,
            "bad": self.bad,
            "good": self.good,
            "mean_error_m": self.mean_error_m,
        }


def error_onsets(
    t1: ArrayLike,
    t2: ArrayLike,
    errors_m: ArrayLike,
    threshold_m: float,
    *,
    min_relations: int = 3,
    max_onsets: int = 10,
) -> list[ErrorOnset]:
    """The onsets of a run's relations error (module docstring), largest first.

    Parameters
    ----------
    t1, t2 : array_like, shape (n,)
        The relations' two time stamps (s); either may be the later.
    errors_m : array_like, shape (n,)
        Each relation's translation error (m), e.g. from
        :func:`slam.evaluation.relations_metric.relation_errors`.  Any other error per
        relation works the same, with ``threshold_m`` and the onsets' ``mean_error_m`` in its
        unit (``scripts/error_onsets.py --threshold-deg``: the rotation error in degrees).
    threshold_m : float
        A relation erring by more than this is bad (m).
    min_relations : int
        An onset must explain at least this many bad relations more than the good ones it
        spans.
    max_onsets : int
        At most this many onsets.

    Returns
    -------
    list of ErrorOnset
        In the order found (each explaining the most of what the earlier ones left).
    """
    a = np.asarray(t1, dtype=np.float64)
    b = np.asarray(t2, dtype=np.float64)
    err = np.asarray(errors_m, dtype=np.float64)
    if a.ndim != 1 or a.shape != b.shape or a.shape != err.shape:
        raise EvaluationError(
            f"error_onsets: t1, t2 and errors_m must be 1-D of one length, got "
            f"{a.shape}, {b.shape}, {err.shape}"
        )
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b)) and np.all(np.isfinite(err))):
        raise EvaluationError("error_onsets: time stamps and errors must be finite")
    if not (np.isfinite(threshold_m) and threshold_m >= 0.0):
        raise EvaluationError(f"error_onsets: threshold_m must be >= 0, got {threshold_m}")
    if min_relations < 1 or max_onsets < 0:
        raise EvaluationError("error_onsets: min_relations must be >= 1, max_onsets >= 0")
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    keep = hi > lo  # a relation between two scans of one time stamp spans nothing
    lo, hi, err = lo[keep], hi[keep], err[keep]
    stamps = np.unique(np.concatenate([lo, hi]))
    if stamps.size < 2:
        return []
    # relation k spans the intervals [stamps[i], stamps[i+1]) for first[k] <= i < last[k]
    first = np.searchsorted(stamps, lo)
    last = np.searchsorted(stamps, hi)
    n_int = stamps.size - 1

    def spanning(mask: NDArray[np.bool_]) -> NDArray[np.int64]:
        step = np.zeros(n_int + 1, dtype=np.int64)
        np.add.at(step, first[mask], 1)
        np.add.at(step, last[mask], -1)
        return np.cumsum(step)[:n_int]

    bad = err > threshold_m
    good_count = spanning(~bad)
    open_bad = bad.copy()
    onsets: list[ErrorOnset] = []
    while len(onsets) < max_onsets and open_bad.any():
        balance = spanning(open_bad) - good_count
        i = int(np.argmax(balance))
        if balance[i] < min_relations:
            break
        j = i  # the intervals after it with the same balance: the step may lie in any
        while j + 1 < n_int and balance[j + 1] == balance[i]:
            j += 1
        explained = open_bad & (first <= i) & (last > i)
        onsets.append(
            ErrorOnset(
                from_s=float(stamps[i]),
                until_s=float(stamps[j + 1]),
                bad=int(explained.sum()),
                good=int(good_count[i]),
                mean_error_m=float(err[explained].mean()),
            )
        )
        open_bad &= ~explained
    return onsets
