"""The state passed between the steps of a batched extraction.

:class:`Groups` are candidate lines before a fit (memberships and start angles);
:class:`Fitted` are fitted lines with their covariances and segments.  Both hold the lines of
all the scans of a batch as flat arrays with a scan id per line.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from linefit.covariance import LineCovariances
from linefit.fit import GroupFit

__all__ = ["Fitted", "Groups", "fit_cat", "fit_take"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


@dataclass(frozen=True, eq=False)
class Fitted:
    """Fitted lines: memberships (``gidx`` ascending), fits, covariances and segments.

    ``order`` sorts the memberships by (line, u_S); ``seg`` numbers the segments along
    ``order`` (non-decreasing, lines in ascending order).
    """

    pidx: IntArray
    gidx: IntArray
    n_groups: int
    gscan: IntArray
    fit: GroupFit
    cov: LineCovariances
    order: IntArray
    seg: IntArray

    def select(self, keep_g: NDArray[np.bool_]) -> Fitted:
        """Only the lines ``keep_g`` (renumbered in order)."""
        new_g = np.cumsum(keep_g) - 1
        keep_m = keep_g[self.gidx]
        new_m = np.cumsum(keep_m) - 1
        f, c = self.fit, self.cov
        kept_sorted = keep_m[self.order]
        _, seg = np.unique(self.seg[kept_sorted], return_inverse=True)
        fit = fit_take(f, keep_g, keep_m)
        cov = LineCovariances(c.cov[keep_g], c.end_var[keep_m], c.gain_alpha[keep_m])
        return Fitted(
            self.pidx[keep_m],
            new_g[self.gidx[keep_m]],
            int(keep_g.sum()),
            self.gscan[keep_g],
            fit,
            cov,
            new_m[self.order[kept_sorted]],
            seg.reshape(-1).astype(np.intp),
        )

    @staticmethod
    def concat(a: Fitted, b: Fitted) -> Fitted:
        """The lines of ``a`` followed by those of ``b``."""
        fit = fit_cat(a.fit, b.fit)
        cov = LineCovariances(
            np.concatenate([a.cov.cov, b.cov.cov]),
            np.concatenate([a.cov.end_var, b.cov.end_var]),
            np.concatenate([a.cov.gain_alpha, b.cov.gain_alpha]),
        )
        n_seg_a = int(a.seg[-1]) + 1 if a.seg.shape[0] else 0
        return Fitted(
            np.concatenate([a.pidx, b.pidx]),
            np.concatenate([a.gidx, b.gidx + a.n_groups]),
            a.n_groups + b.n_groups,
            np.concatenate([a.gscan, b.gscan]),
            fit,
            cov,
            np.concatenate([a.order, b.order + a.pidx.shape[0]]),
            np.concatenate([a.seg, b.seg + n_seg_a]),
        )


_PER_LINE = ("r", "alpha", "s", "converged", "iterations")
_PER_MEMBER = ("u_r", "u_s", "p_r", "p_s", "p_rs", "w_r", "w_s")


@dataclass
class Groups:
    """Memberships (sorted by group) with per-group start angle and scan."""

    pidx: IntArray
    gidx: IntArray
    n: int
    alpha0: FloatArray
    gscan: IntArray

    def keep_groups(self, keep_g: NDArray[np.bool_]) -> None:
        """Keep only the groups ``keep_g`` (renumbered in order) and their members."""
        new_id = np.cumsum(keep_g) - 1
        keep = keep_g[self.gidx]
        self.pidx = self.pidx[keep]
        self.gidx = new_id[self.gidx[keep]]
        self.n = int(keep_g.sum())
        self.alpha0 = self.alpha0[keep_g]
        self.gscan = self.gscan[keep_g]

    def keep_members(self, keep: NDArray[np.bool_]) -> None:
        """Keep only the memberships ``keep``."""
        self.pidx = self.pidx[keep]
        self.gidx = self.gidx[keep]

    def subset(self, keep_g: NDArray[np.bool_], keep_m: NDArray[np.bool_] | None = None) -> Groups:
        """A copy with only the groups ``keep_g`` (and, if given, only the members ``keep_m``)."""
        out = Groups(self.pidx, self.gidx, self.n, self.alpha0, self.gscan)
        if keep_m is not None:
            out.keep_members(keep_m)
        out.keep_groups(keep_g)
        return out

    @staticmethod
    def cat(a: Groups, b: Groups) -> Groups:
        """The groups of ``a`` followed by those of ``b``."""
        return Groups(
            np.concatenate([a.pidx, b.pidx]),
            np.concatenate([a.gidx, b.gidx + a.n]),
            a.n + b.n,
            np.concatenate([a.alpha0, b.alpha0]),
            np.concatenate([a.gscan, b.gscan]),
        )


def fit_take(fit: GroupFit, keep_g: NDArray[np.bool_], keep_m: NDArray[np.bool_]) -> GroupFit:
    """The fits of the lines ``keep_g`` (whose memberships are ``keep_m``)."""
    return GroupFit(
        **{k: getattr(fit, k)[keep_g] for k in _PER_LINE},
        **{k: getattr(fit, k)[keep_m] for k in _PER_MEMBER},
        weighted=fit.weighted,
    )


def fit_cat(a: GroupFit, b: GroupFit) -> GroupFit:
    """The fits of ``a`` followed by those of ``b``."""
    return GroupFit(
        **{k: np.concatenate([getattr(a, k), getattr(b, k)]) for k in _PER_LINE},
        **{k: np.concatenate([getattr(a, k), getattr(b, k)]) for k in _PER_MEMBER},
        weighted=a.weighted,
    )
