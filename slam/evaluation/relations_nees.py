"""Relations NEES: the consistency of a run's covariances measured on real logs.

Ground truth on the public logs is a set of relative poses (Kümmerle et al. relations), not
poses.  For each relation ``(t1, t2, ρ*)`` the estimated relative pose is ``ρ̂ = p(t1)⁻¹ p(t2)``
(the trajectory as reported, as the relations metric reads it), its error the tangent vector
that moves it onto the relation, ``e = Log(ρ̂⁻¹ ρ*)`` (right perturbation, planar: the
relation's ``x``, ``y``, ``yaw``), and its NEES ``eᵀ C⁻¹ e`` with ``C`` the covariance of
``ρ̂`` from the joint marginal of the two poses (supplied by the caller, e.g.
:class:`slam.graph.relative.RunCovariances` from the run's ``graph.g2o``), in the same frame
and tangent space.

Reported: the mean over the ``N`` relations with the two-sided interval of a mean of ``N``
independent ``χ²₃`` values, ``[χ²₃ₙ(2.5 %), χ²₃ₙ(97.5 %)] / N``, and, when the caller can draw
the relations' errors jointly under the run's own model (``error_draws``, e.g.
:meth:`slam.graph.relative.RunCovariances.relation_error_draws`), the interval of the mean for
*one* run: relations share poses and loop closures, so their errors are correlated and the
mean spreads wider than for independent ones.  It is the 2.5 % / 97.5 % quantiles of the
mean NEES over :data:`ONE_RUN_DRAWS` seeded joint draws (with the relations' own covariance,
each draw gets an independent relation error of that covariance too, a negative variance of
it drawn as zero); the effective degrees of freedom ``2 E² / Var`` of those means say how
many independent ``χ²₁`` terms would spread as much.  The one-run interval decides
``consistent`` when it is there.  Also the median (``χ²₃``: 2.37), the fraction of
relations whose error lies inside its own 95 % ellipsoid (NEES ≤ ``χ²₃(95 %)`` = 7.81; 0.95
expected), and the means of the translation part (``e_xyᵀ C_xy⁻¹ e_xy``, 2 expected) and of
the heading part (``e_θ² / C_θθ``, 1 expected), which say which part of the covariance is
off, and the same per time gap between the two scans (< 10 s: the local covariances; ≥ 60 s:
across loop closures).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slam.errors import EvaluationError
from slam.evaluation.nees import CorrelatedBounds, nees_bounds, nees_values, psd_factor
from slam.evaluation.timestamps import match_timestamps
from slam.geometry import pose_between, pose_log
from slam.io.relations import Relations
from slam.io.trajectory import Trajectory

__all__ = ["RelationCovariances", "RelationsNees", "relation_error_vectors", "relations_nees"]

FloatArray = NDArray[np.float64]

GAP_CLASSES_S = ((0.0, 10.0), (10.0, 60.0), (60.0, float("inf")))
"""Time gaps ``|t2 − t1|`` (s) of :meth:`RelationsNees.by_gap`."""

ONE_RUN_DRAWS = 2000
"""Joint draws of the relations' errors behind the one-run interval (its bounds to a few per
cent; the lower bound of a single χ²₃ to about 10 %)."""

ONE_RUN_SEED = 20090512
"""Seed of those draws (and of the relations' own errors added to them)."""

RelationErrorDraws = Callable[[FloatArray, FloatArray, int, int], Iterable[FloatArray]]
"""``draws(t1, t2, n, seed)``: ``n`` joint draws of the errors of ``pose(t1)⁻¹ pose(t2)`` under
the run's model, in chunks ``(k, m, 3)`` (the frame and tangent space of the covariances)."""

RelationCovariances = Callable[[FloatArray, FloatArray], FloatArray]
"""``cov(t1, t2) -> (m, 3, 3)``: covariance of each ``pose(t1)⁻¹ pose(t2)`` (right tangent
space of the relative pose, the frame of the trajectory)."""


def relation_error_vectors(
    pose_1: FloatArray, pose_2: FloatArray, relations: Relations
) -> FloatArray:
    """``Log(ρ̂⁻¹ ρ*)`` ``(m, 3)`` with ``ρ̂ = pose_1⁻¹ pose_2`` and ``ρ*`` the planar relation."""
    estimated = pose_between(np.asarray(pose_1, float), np.asarray(pose_2, float))
    return np.asarray(pose_log(pose_between(estimated, relations.poses)))


@dataclass(frozen=True)
class RelationsNees:
    """Relations NEES of a run (module docstring)."""

    n: int
    mean: float
    median: float
    lower: float
    upper: float
    fraction_inside_95: float
    mean_translation: float
    mean_rotation: float
    single_bound_95: float
    values: FloatArray = field(repr=False, default_factory=lambda: np.zeros(0))
    gaps_s: FloatArray = field(repr=False, default_factory=lambda: np.zeros(0))
    t1_s: FloatArray = field(repr=False, default_factory=lambda: np.zeros(0))
    t2_s: FloatArray = field(repr=False, default_factory=lambda: np.zeros(0))
    dof: int = 3
    one_run: CorrelatedBounds | None = None

    def by_gap(self) -> list[dict[str, Any]]:
        """Count, mean and median per time gap ``|t2 − t1|`` (< 10 s, 10-60 s, ≥ 60 s).

        Short relations test the local covariances (odometry, lines), long ones those across
        loop closures.
        """
        out = []
        for lo, hi in GAP_CLASSES_S:
            sel = (self.gaps_s >= lo) & (self.gaps_s < hi)
            v = self.values[sel]
            out.append(
                {
                    "gap_s": [lo, hi if np.isfinite(hi) else None],
                    "n": int(v.size),
                    "mean": float(v.mean()) if v.size else None,
                    "median": float(np.median(v)) if v.size else None,
                }
            )
        return out

    @property
    def interval(self) -> tuple[float, float]:
        """The 95 % interval the mean is tested against: one run's when there is one."""
        if self.one_run is not None:
            return self.one_run.lower, self.one_run.upper
        return self.lower, self.upper

    @property
    def consistent(self) -> bool:
        """The mean lies inside :attr:`interval`."""
        lo, hi = self.interval
        return lo <= self.mean <= hi

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (``metrics.json``'s ``relations_nees``; no per-relation values)."""
        return {
            "n": self.n,
            "dof": self.dof,
            "mean": self.mean,
            "median": self.median,
            "bounds_95": [self.lower, self.upper],
            "consistent": self.consistent,
            "fraction_inside_95": self.fraction_inside_95,
            "single_bound_95": self.single_bound_95,
            "mean_translation": self.mean_translation,
            "mean_rotation": self.mean_rotation,
            "by_gap": self.by_gap(),
            **(
                {
                    "one_run": {
                        "bounds_95": [self.one_run.lower, self.one_run.upper],
                        "effective_dof": self.one_run.effective_dof,
                        "draws": ONE_RUN_DRAWS,
                    }
                }
                if self.one_run is not None
                else {}
            ),
        }


def relations_nees(
    trajectory: Trajectory,
    relations: Relations,
    covariances: RelationCovariances,
    *,
    tolerance_s: float = 1e-5,
    relations_cov: FloatArray | None = None,
    error_draws: RelationErrorDraws | None = None,
) -> RelationsNees:
    """NEES of every relation whose two time stamps are poses of ``trajectory``.

    Relations with a stamp that is not in the trajectory are left out (the relations metric
    counts and judges them); a covariance that is not positive definite is an
    :class:`~slam.errors.EvaluationError`.  ``relations_cov`` (3, 3), the relations' own
    covariance (:mod:`slam.evaluation.reference_noise`), is added to every run covariance:
    the NEES then tests the run's covariance against errors that include the relations'.
    With ``error_draws`` the one-run interval is computed too (module docstring).
    """
    i1, ok1 = match_timestamps(relations.t1, trajectory.timestamps, tolerance_s)
    i2, ok2 = match_timestamps(relations.t2, trajectory.timestamps, tolerance_s)
    used = ok1 & ok2
    if not used.any():
        raise EvaluationError("no relation has both time stamps in the trajectory")
    sub = relations.subset(used)
    e = relation_error_vectors(trajectory.poses[i1[used]], trajectory.poses[i2[used]], sub)
    cov = np.asarray(
        covariances(trajectory.timestamps[i1[used]], trajectory.timestamps[i2[used]]), float
    )
    if relations_cov is not None:
        cov = cov + np.asarray(relations_cov, dtype=float)[None, :, :]
    values = nees_values(e, cov)
    trans = nees_values(e[:, :2], cov[:, :2, :2])
    rot = e[:, 2] ** 2 / cov[:, 2, 2]
    n = int(values.size)
    lower, upper = nees_bounds(3, n, 0.95)
    from scipy.stats import chi2  # here: importing scipy.stats costs ~1 s at start-up

    single = float(chi2.ppf(0.95, 3))
    one_run = None
    if error_draws is not None:
        t1, t2 = trajectory.timestamps[i1[used]], trajectory.timestamps[i2[used]]
        draws = error_draws(t1, t2, ONE_RUN_DRAWS, ONE_RUN_SEED)
        one_run = _one_run_interval(draws, cov, relations_cov)
    return RelationsNees(
        n=n,
        mean=float(values.mean()),
        median=float(np.median(values)),
        lower=lower,
        upper=upper,
        fraction_inside_95=float(np.mean(values <= single)),
        mean_translation=float(trans.mean()),
        mean_rotation=float(rot.mean()),
        single_bound_95=single,
        values=values,
        gaps_s=np.abs(sub.t2 - sub.t1),
        t1_s=sub.t1,
        t2_s=sub.t2,
        one_run=one_run,
    )


def _one_run_interval(
    draws: Iterable[FloatArray], cov: FloatArray, relations_cov: FloatArray | None
) -> CorrelatedBounds:
    """Quantiles of the mean NEES over joint draws of the errors (module docstring)."""
    L = np.linalg.cholesky(cov)
    rng = np.random.default_rng(ONE_RUN_SEED + 1)
    # the three-cornered hat can estimate a variance below zero: drawn as zero
    R = None if relations_cov is None else psd_factor(relations_cov)
    means = []
    for eta in draws:
        if R is not None:
            eta = eta + rng.standard_normal(eta.shape) @ R.T
        z = np.linalg.solve(L[None], eta[..., None])[..., 0]  # (k, m, 3), whitened
        means.append(np.mean(np.sum(z**2, axis=-1), axis=1))
    m = np.concatenate(means)
    lower, upper = np.quantile(m, [0.025, 0.975])
    return CorrelatedBounds(
        lower=float(lower),
        upper=float(upper),
        effective_dof=float(2.0 * m.mean() ** 2 / m.var()),
        n=int(cov.shape[0]),
    )
