"""Normalised estimation error squared (NEES) of poses with covariances and ground truth.

For each pose with covariance ``P`` (3×3, in the right-perturbation tangent space of
:mod:`slam.geometry`, as GTSAM's ``Pose2`` marginals), the error is the tangent vector that
moves the estimate onto the truth, ``ξ = Log(P̂⁻¹ · Q)`` (so ``Q = P̂ ⊕ ξ``), and
``NEES = ξᵀ P⁻¹ ξ``.  A consistent estimator has ``E[NEES] = 3``; the mean over ``N`` poses
is tested against the two-sided χ² interval ``[χ²_{3N}(α/2), χ²_{3N}(1 − α/2)] / N``
(:func:`nees_bounds`; Bar-Shalom, Li & Kirubarajan 2001, §5.4), and the fraction of single
poses inside the ``χ²_3`` interval is reported too.  (Successive poses of one trajectory are
correlated, so the interval of the mean is indicative for a single run, exact for the
average over independent Monte-Carlo runs at one time step, the ANEES.)

The poses of one run are not independent: a heading error early on moves every later pose, so
a single run's mean NEES spreads far wider than the interval of ``3N`` independent degrees of
freedom.  Given the joint covariance of the poses' errors (the estimator's own, e.g. from the
run's ``graph.g2o``, :meth:`slam.graph.relative.RunCovariances.joint_scan_covariance`),
:func:`correlated_nees_bounds` gives the interval of the mean for *one* run: if the errors
``ξ`` are ``N(0, Σ)`` (Σ over all poses jointly), the mean NEES ``(1/N) Σᵢ ξᵢᵀ Pᵢ⁻¹ ξᵢ``
(``Pᵢ`` the diagonal blocks) is a weighted sum ``Σₖ λₖ zₖ²`` of independent ``χ²₁`` variables,
``λₖ`` the eigenvalues of ``W^½ Σ W^½ / N`` with ``W = diag(Pᵢ⁻¹)`` (their sum is 3); its
quantiles are taken from :data:`BOUND_DRAWS` seeded draws of that sum.  ``(Σλ)² / Σλ²``, the
number of independent ``χ²₁`` terms with the same spread, is reported as the effective degrees
of freedom.

:func:`pose_nees` pairs two trajectories by time stamp and requires every covariance to be
positive definite; :func:`pose_nees_values` pairs arrays by index and marks poses without a
usable covariance undefined (``nan``), as experiments need for per-time-step curves.

No alignment is applied: the estimate and the truth must share the world frame (the
simulator and the SLAM runner both anchor the first pose).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slam.errors import EvaluationError
from slam.evaluation.timestamps import associate
from slam.geometry import pose_between, pose_log
from slam.io.trajectory import Trajectory

__all__ = [
    "CorrelatedBounds",
    "NeesResult",
    "correlated_nees_bounds",
    "nees_bounds",
    "nees_values",
    "pose_nees",
    "pose_nees_values",
    "psd_factor",
]

FloatArray = NDArray[np.float64]

BOUND_DRAWS = 200_000
"""Draws of the weighted ``χ²`` sum behind :func:`correlated_nees_bounds` (the 2.5 % and 97.5 %
quantiles to about 1 %: 0.216 / 9.28 for one pose, exactly 0.216 / 9.35)."""

EXACT_TERMS = 256
"""Largest weights of that sum drawn term by term (the rest as one moment-matched ``χ²``)."""

BOUND_SEED = 20030514
"""Seed of those draws: the same covariance gives the same interval."""

MAX_BOUND_POSES = 1000
"""At most this many poses (evenly spaced) enter the joint covariance of :func:`pose_nees`'s
one-run interval; the mean NEES is then tested over the same poses."""

JointCovariance = Callable[[FloatArray], FloatArray]
"""``joint(timestamps) -> (3m, 3m)``: the joint covariance of the errors of the poses at these
``m`` time stamps (right tangent spaces, pose by pose, in the trajectory's frame)."""


def nees_values(errors: ArrayLike, covariances: ArrayLike) -> FloatArray:
    """``ξᵀ P⁻¹ ξ`` for errors ``(n, d)`` and covariances ``(n, d, d)`` (Cholesky, checked).

    Raises
    ------
    EvaluationError
        When a covariance is not positive definite (its index and eigenvalues are named).
    """
    e = np.asarray(errors, dtype=np.float64)
    c = np.asarray(covariances, dtype=np.float64)
    if c.shape != e.shape + e.shape[-1:]:
        raise EvaluationError(f"covariances {c.shape} do not fit errors {e.shape}")
    try:
        L = np.linalg.cholesky(c)
    except np.linalg.LinAlgError:
        eig = np.linalg.eigvalsh(0.5 * (c + np.swapaxes(c, -1, -2)))
        bad = int(np.flatnonzero(eig.min(axis=-1) <= 0.0)[0]) if (eig <= 0).any() else -1
        raise EvaluationError(
            f"covariance {bad} is not positive definite (eigenvalues {eig[bad].tolist()})"
        ) from None
    z = np.linalg.solve(L, e[..., None])[..., 0]
    return np.sum(z**2, axis=-1)


def psd_factor(cov: ArrayLike) -> FloatArray:
    """``L`` with ``L Lᵀ = cov``, for drawing ``N(0, cov)``.

    Eigen-decomposition of the symmetric part; a negative eigenvalue (an estimated covariance
    can have one) is taken as zero.
    """
    c = np.asarray(cov, dtype=np.float64)
    eig, vec = np.linalg.eigh(0.5 * (c + c.T))
    return np.asarray(vec * np.sqrt(np.clip(eig, 0.0, None)))


def nees_bounds(dof: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Two-sided interval of the mean of ``n`` independent NEES values of ``dof`` each.

    A consistent estimator's NEES values are ``χ²_dof``; their sum over ``n`` independent
    samples (poses, or Monte-Carlo runs at one time step) is ``χ²_{n·dof}``, so the mean lies in
    ``[χ²_{n·dof}((1 − c)/2), χ²_{n·dof}((1 + c)/2)] / n`` with probability ``c``.  With
    ``n = 1`` this is the interval of a single pose's NEES.

    Parameters
    ----------
    dof : int
        Dimension of each error (3 for a planar pose).
    n : int
        Number of NEES values averaged.
    confidence : float
        Probability ``c`` of the interval, in (0, 1).

    Returns
    -------
    tuple of float
        ``(lower, upper)`` bounds of the mean NEES (dimensionless).
    """
    from scipy.stats import chi2  # here: importing scipy.stats costs ~1 s at start-up

    alpha = 1.0 - confidence
    lower = float(chi2.ppf(alpha / 2.0, dof * n) / n)
    upper = float(chi2.ppf(1.0 - alpha / 2.0, dof * n) / n)
    return lower, upper


@dataclass(frozen=True)
class CorrelatedBounds:
    """Interval of one run's mean NEES whose poses' errors are correlated.

    Attributes
    ----------
    lower, upper : float
        The two-sided interval of the mean (dimensionless).
    effective_dof : float
        ``(Σλ)² / Σλ²``: independent ``χ²₁`` terms with the same spread (``dof · n`` for
        independent poses).
    n : int
        Poses in the joint covariance.
    """

    lower: float
    upper: float
    effective_dof: float
    n: int


def correlated_nees_bounds(
    joint_covariance: ArrayLike, dof: int = 3, confidence: float = 0.95
) -> CorrelatedBounds:
    """Interval of the mean of ``n`` NEES values whose errors are jointly ``N(0, Σ)``.

    Each value is ``ξᵢᵀ Pᵢ⁻¹ ξᵢ`` with ``Pᵢ`` the ``i``-th ``dof × dof`` diagonal block of
    ``Σ`` (module docstring).

    Parameters
    ----------
    joint_covariance : array_like, shape (n·dof, n·dof)
        ``Σ``, symmetric positive semi-definite with positive-definite diagonal blocks.
    dof : int
        Dimension of each error.
    confidence : float
        Probability of the interval, in (0, 1).

    Raises
    ------
    EvaluationError
        When ``Σ`` is not square of a multiple of ``dof``, not finite, or a diagonal block is
        not positive definite (its index is named).
    """
    S = np.asarray(joint_covariance, dtype=np.float64)
    if S.ndim != 2 or S.shape[0] != S.shape[1] or S.shape[0] == 0 or S.shape[0] % dof:
        raise EvaluationError(f"joint covariance of shape {S.shape} is not (n*{dof}, n*{dof})")
    if not np.all(np.isfinite(S)):
        raise EvaluationError("joint covariance has non-finite entries")
    n = S.shape[0] // dof
    S = 0.5 * (S + S.T)
    blocks = S.reshape(n, dof, n, dof)[np.arange(n), :, np.arange(n), :]
    try:
        L = np.linalg.cholesky(blocks)
    except np.linalg.LinAlgError:
        eig = np.linalg.eigvalsh(blocks).min(axis=-1)
        bad = int(np.flatnonzero(~(eig > 0.0))[0])
        raise EvaluationError(
            f"joint covariance: block of pose {bad} is not positive definite"
        ) from None
    # whitened per pose: M = T Σ Tᵀ with T = diag(Lᵢ⁻¹), so W^½ Σ W^½ has the same spectrum
    Linv = np.linalg.inv(L)
    T = np.zeros_like(S)
    for i in range(n):
        T[i * dof : (i + 1) * dof, i * dof : (i + 1) * dof] = Linv[i]
    lam = np.clip(np.linalg.eigvalsh(T @ S @ T.T), 0.0, None)[::-1] / n  # largest first
    # the largest EXACT_TERMS weights drawn term by term; the rest (small weights, many terms:
    # nearly normal) as one scaled χ² with their mean and variance (Satterthwaite)
    top, rest = lam[:EXACT_TERMS], lam[EXACT_TERMS:]
    rng = np.random.default_rng(BOUND_SEED)
    sums = np.zeros(BOUND_DRAWS)
    chunk = max(1, 4_000_000 // top.size)
    for start in range(0, BOUND_DRAWS, chunk):
        z = rng.standard_normal((min(chunk, BOUND_DRAWS - start), top.size))
        sums[start : start + z.shape[0]] = np.square(z) @ top
    if rest.sum() > 0.0:
        scale = float(np.sum(rest**2) / rest.sum())
        sums += scale * rng.chisquare(rest.sum() / scale, BOUND_DRAWS)
    alpha = 1.0 - confidence
    lower, upper = np.quantile(sums, [alpha / 2.0, 1.0 - alpha / 2.0])
    return CorrelatedBounds(
        lower=float(lower),
        upper=float(upper),
        effective_dof=float(lam.sum() ** 2 / np.sum(lam**2)),
        n=n,
    )


def _pose_errors(poses_est: FloatArray, poses_true: FloatArray) -> FloatArray:
    """Tangent vectors ``ξ = Log(P̂⁻¹ · Q)`` that move each estimate onto its truth."""
    return pose_log(pose_between(poses_est, poses_true))


def pose_nees_values(
    poses_est: ArrayLike, covariances: ArrayLike, poses_true: ArrayLike
) -> FloatArray:
    """NEES of each estimated pose against the true pose at the same index.

    The poses are paired by position in the arrays (for trajectories paired by time stamp,
    :func:`pose_nees`).  A pose whose covariance is not finite or not positive definite (an
    anchored first pose has zero covariance) gets ``nan``: its NEES is undefined.

    Parameters
    ----------
    poses_est, poses_true : array_like, shape (..., 3)
        Estimated and true poses ``(x, y, θ)`` (m, m, rad) in one world frame.
    covariances : array_like, shape (..., 3, 3)
        Covariances of the estimates in the right-perturbation tangent space.

    Returns
    -------
    ndarray, shape (...)
        ``ξᵀ P⁻¹ ξ`` per pose (dimensionless); ``nan`` where the covariance is unusable.
    """
    est = np.asarray(poses_est, dtype=np.float64)
    cov = np.asarray(covariances, dtype=np.float64)
    truth = np.asarray(poses_true, dtype=np.float64)
    if est.shape != truth.shape or est.shape[-1:] != (3,) or cov.shape != (*est.shape, 3):
        raise EvaluationError(
            f"pose_nees_values: shapes {est.shape}, {cov.shape}, {truth.shape} do not match"
        )
    xi = _pose_errors(est, truth).reshape(-1, 3)
    cov = cov.reshape(-1, 3, 3)
    usable = np.all(np.isfinite(cov), axis=(1, 2))
    smallest = np.full(cov.shape[0], -np.inf)
    if np.any(usable):
        sym = 0.5 * (cov[usable] + np.swapaxes(cov[usable], 1, 2))
        smallest[usable] = np.linalg.eigvalsh(sym)[:, 0]
    usable &= smallest > 0.0
    out = np.full(cov.shape[0], np.nan)
    out[usable] = nees_values(xi[usable], cov[usable])
    return out.reshape(est.shape[:-1])


@dataclass(frozen=True)
class NeesResult:
    """Pose NEES with its χ² consistency bounds.

    Attributes
    ----------
    n, dof : int
        Poses and the dimension of each error.
    mean : float
        Mean NEES over the ``n`` poses.
    lower, upper : float
        Interval of the mean of ``n`` independent poses (:func:`nees_bounds`): exact for the
        average over independent Monte-Carlo runs, far too narrow for one run.
    confidence : float
    fraction_within : float
        Fraction of poses inside the single-pose interval.
    one_run : CorrelatedBounds or None
        Interval of this run's mean with the poses' correlation (:func:`correlated_nees_bounds`),
        when the joint covariance was given.
    one_run_mean : float or None
        The mean NEES over the poses of ``one_run`` (``mean`` unless there were more than
        :data:`MAX_BOUND_POSES` poses).
    values : ndarray
        Per-pose NEES.
    """

    n: int
    dof: int
    mean: float
    lower: float
    upper: float
    confidence: float
    fraction_within: float
    values: FloatArray = field(repr=False)
    one_run: CorrelatedBounds | None = None
    one_run_mean: float | None = None

    @property
    def consistent(self) -> bool:
        """The mean NEES lies inside its interval: the one-run interval when there is one."""
        if self.one_run is not None and self.one_run_mean is not None:
            return self.one_run.lower <= self.one_run_mean <= self.one_run.upper
        return self.lower <= self.mean <= self.upper

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready copy (per-pose values left out)."""
        out: dict[str, Any] = {
            "n": self.n,
            "dof": self.dof,
            "mean": self.mean,
            "bounds": [self.lower, self.upper],
            "confidence": self.confidence,
            "consistent": self.consistent,
            "fraction_within_single_bounds": self.fraction_within,
        }
        if self.one_run is not None:
            out["one_run"] = {
                "bounds": [self.one_run.lower, self.one_run.upper],
                "mean": self.one_run_mean,
                "n": self.one_run.n,
                "effective_dof": self.one_run.effective_dof,
            }
        return out


def pose_nees(
    estimate: Trajectory,
    covariances: ArrayLike,
    ground_truth: Trajectory,
    *,
    confidence: float = 0.95,
    tolerance_s: float = 1e-5,
    max_unmatched_fraction: float = 0.02,
    joint_covariance: JointCovariance | None = None,
) -> NeesResult:
    """NEES of every estimated pose that has a ground-truth pose of the same stamp.

    Every matched pose must have a positive-definite covariance (else
    :class:`~slam.errors.EvaluationError`), except a pose whose covariance is exactly zero: the
    gauge (the EKF's first pose, which defines the world frame), left out of the NEES.
    :func:`pose_nees_values` instead marks every unusable pose undefined.  The mean is tested
    against :func:`nees_bounds` of the matched poses, each pose against the single-pose
    interval; with ``joint_covariance`` (the joint covariance of the poses at given time
    stamps) also against the one-run interval (:func:`correlated_nees_bounds`), over at most
    :data:`MAX_BOUND_POSES` evenly spaced poses, which then decides ``consistent``.
    """
    cov = np.asarray(covariances, dtype=np.float64)
    if cov.shape != (len(estimate), 3, 3):
        raise EvaluationError(f"need one 3x3 covariance per pose, got shape {cov.shape}")
    i_est, i_ref, _ = associate(
        estimate,
        ground_truth,
        tolerance_s=tolerance_s,
        max_unmatched_fraction=max_unmatched_fraction,
    )
    gauge = ~np.any(cov[i_est] != 0.0, axis=(1, 2))
    i_est, i_ref = i_est[~gauge], i_ref[~gauge]
    if i_est.size == 0:
        raise EvaluationError("every matched pose has a zero covariance: no NEES")
    values = nees_values(_pose_errors(estimate.poses[i_est], ground_truth.poses[i_ref]), cov[i_est])
    n, dof = values.size, 3
    lower, upper = nees_bounds(dof, n, confidence)
    single_lower, single_upper = nees_bounds(dof, 1, confidence)
    single = (values >= single_lower) & (values <= single_upper)
    one_run = one_run_mean = None
    if joint_covariance is not None:
        sel = np.unique(np.linspace(0, n - 1, min(n, MAX_BOUND_POSES)).round().astype(np.intp))
        one_run = correlated_nees_bounds(
            joint_covariance(estimate.timestamps[i_est[sel]]), dof, confidence
        )
        one_run_mean = float(values[sel].mean())
    return NeesResult(
        n=int(n),
        dof=dof,
        mean=float(values.mean()),
        lower=lower,
        upper=upper,
        confidence=confidence,
        fraction_within=float(single.mean()),
        values=values,
        one_run=one_run,
        one_run_mean=one_run_mean,
    )
