"""The relations' own scatter, from the run and the odometry: the three-cornered hat.

A relation ``ρ*`` of the public logs is itself a measurement (scan matching, checked by
hand), not the truth.  Its error enters every comparison: the relations NEES of a perfectly
consistent run is ``E[eᵀ C⁻¹ e] = 3 + tr(C⁻¹ R)`` with ``R`` the relation's own covariance, so
where ``R`` is not small against the run's covariance ``C`` the NEES says more about the
relations than about the run.

Three measurements of the same relative motion — the run ``a``, the log's odometry ``b`` and
the relation ``r`` — give each one's noise without knowing the truth (the *three-cornered
hat*, Gray & Allan 1974): with ``e_a = a ⊖ r`` and ``e_b = b ⊖ r`` (tangent vectors, per
component ``k``) and the three errors independent and zero-mean,

``E[e_a²] = σ_a² + σ_r²``,  ``E[e_b²] = σ_b² + σ_r²``,  ``E[(e_a − e_b)²] = σ_a² + σ_b²``,

so ``σ_r² = (E[e_a²] + E[e_b²] − E[(e_a − e_b)²]) / 2``, and alike for ``σ_a²`` and ``σ_b²``
(means of squares: a bias counts as noise).  A negative estimate (sampling noise, or errors
that are not independent) is reported as it is and used as zero.

Only short relations (``|t2 − t1| <`` ``max_gap_s``) are used: over them the odometry is a
measurement of the motion of its own quality, not a drifted trajectory.  The relations come
from matching nearby scans whatever their time gap, so the scatter found there is taken for
all of them.  The run must not be the odometry: a scan between keyframes is placed by its
odometry from the keyframe, so with ``keyframe_timestamps`` only relations between two
keyframes are used (the run's relative pose then comes from the graph).  Even there the run
fuses the odometry with the lines: for an optimal fusion ``E[e_a e_b] = σ_a²``, so the
estimate of ``σ_r²`` exceeds the truth by up to the run's own variance, ``σ_a²``.  It is an
upper bound on the relations' scatter, tight where that scatter is large against the run's
error, and the NEES with it added (:func:`slam.evaluation.relations_nees.relations_nees`,
``relations_cov``) a lower bound on the run's: the plain relations NEES and this one bracket
the run's consistency.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slam.errors import EvaluationError
from slam.evaluation.relations_nees import relation_error_vectors
from slam.evaluation.timestamps import match_timestamps
from slam.io.relations import Relations
from slam.io.trajectory import Trajectory

__all__ = ["RelationNoise", "relation_noise", "three_cornered_hat"]

FloatArray = NDArray[np.float64]

SHORT_GAP_S = 10.0
"""Relations shorter than this (s) estimate the relations' scatter."""


def three_cornered_hat(
    errors_a: ArrayLike, errors_b: ArrayLike
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Per-component noise variances of a reference and two estimates compared with it.

    Parameters
    ----------
    errors_a, errors_b : array_like, shape (m, k)
        Errors of two independent estimates against the same reference, row by row.

    Returns
    -------
    var_reference, var_a, var_b : ndarray, shape (k,)
        Mean-square noise of the reference and of each estimate (module docstring; may be
        negative where the data do not support the independence assumption).
    """
    a = np.asarray(errors_a, dtype=float)
    b = np.asarray(errors_b, dtype=float)
    if a.ndim != 2 or a.shape != b.shape:
        raise EvaluationError(
            f"errors must be two (m, k) arrays of one shape: {a.shape}, {b.shape}"
        )
    if a.shape[0] < 3:
        raise EvaluationError(f"the three-cornered hat needs at least 3 rows, got {a.shape[0]}")
    v_a = np.mean(a**2, axis=0)
    v_b = np.mean(b**2, axis=0)
    v_ab = np.mean((a - b) ** 2, axis=0)
    return (v_a + v_b - v_ab) / 2.0, (v_a + v_ab - v_b) / 2.0, (v_b + v_ab - v_a) / 2.0


@dataclass(frozen=True)
class RelationNoise:
    """The relations' own scatter and that of the run and the odometry (module docstring).

    Attributes
    ----------
    n : int
        Short relations used.
    keyframes_only : bool
        Only relations between two keyframes were used.
    max_gap_s : float
        Their largest time gap (s).
    var_relations, var_run, var_odometry : ndarray, shape (3,)
        Mean-square noise per component ``(x, y, θ)`` of the relation's frame (m², m², rad²),
        as estimated (may be negative).
    odometry_coincides : int
        Relations the odometry matches to within 1 mm and 1 mrad (a relation that *is* the
        odometry: neither the run nor a consistency test can do better there).
    """

    n: int
    keyframes_only: bool
    max_gap_s: float
    var_relations: FloatArray
    var_run: FloatArray
    var_odometry: FloatArray
    odometry_coincides: int

    @property
    def covariance(self) -> FloatArray:
        """``diag(max(var_relations, 0))`` (3, 3): the relations' covariance to add to a run's."""
        return np.diag(np.maximum(self.var_relations, 0.0))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (RMS values, m and rad; negative variances as negative RMS)."""

        def rms(v: FloatArray) -> list[float]:
            return [float(np.sign(x) * np.sqrt(abs(x))) for x in v]

        return {
            "n": self.n,
            "keyframes_only": self.keyframes_only,
            "max_gap_s": self.max_gap_s,
            "rms_relations_xy_theta": rms(self.var_relations),
            "rms_run_xy_theta": rms(self.var_run),
            "rms_odometry_xy_theta": rms(self.var_odometry),
            "odometry_coincides": self.odometry_coincides,
        }


def relation_noise(
    trajectory: Trajectory,
    odometry: Trajectory,
    relations: Relations,
    *,
    max_gap_s: float = SHORT_GAP_S,
    tolerance_s: float = 1e-5,
    keyframe_timestamps: ArrayLike | None = None,
) -> RelationNoise:
    """Three-cornered hat of the short relations against a run and the log's odometry.

    ``trajectory`` and ``odometry`` must be in the relations' frame.  Relations with a time
    stamp missing from either are left out; fewer than 3 left is an
    :class:`~slam.errors.EvaluationError`.  With ``keyframe_timestamps``, only relations
    between two keyframes (module docstring).
    """
    keep = np.abs(relations.t2 - relations.t1) < max_gap_s
    if keyframe_timestamps is not None:
        kf = np.sort(np.asarray(keyframe_timestamps, dtype=float))
        keep &= match_timestamps(relations.t1, kf, tolerance_s)[1]
        keep &= match_timestamps(relations.t2, kf, tolerance_s)[1]
    short = relations.subset(keep)
    i1, ok1 = match_timestamps(short.t1, trajectory.timestamps, tolerance_s)
    i2, ok2 = match_timestamps(short.t2, trajectory.timestamps, tolerance_s)
    j1, okj1 = match_timestamps(short.t1, odometry.timestamps, tolerance_s)
    j2, okj2 = match_timestamps(short.t2, odometry.timestamps, tolerance_s)
    used = ok1 & ok2 & okj1 & okj2
    if int(used.sum()) < 3:
        raise EvaluationError(
            f"{int(used.sum())} short relations (< {max_gap_s:g} s) have both time stamps in the "
            "run (its keyframes, if given) and in the odometry: too few for the relations' "
            "scatter"
        )
    sub = short.subset(used)
    e_run = relation_error_vectors(trajectory.poses[i1[used]], trajectory.poses[i2[used]], sub)
    e_odo = relation_error_vectors(odometry.poses[j1[used]], odometry.poses[j2[used]], sub)
    v_rel, v_run, v_odo = three_cornered_hat(e_run, e_odo)
    coincide = (np.hypot(e_odo[:, 0], e_odo[:, 1]) < 1e-3) & (np.abs(e_odo[:, 2]) < 1e-3)
    return RelationNoise(
        n=int(used.sum()),
        keyframes_only=keyframe_timestamps is not None,
        max_gap_s=max_gap_s,
        var_relations=v_rel,
        var_run=v_run,
        var_odometry=v_odo,
        odometry_coincides=int(coincide.sum()),
    )
