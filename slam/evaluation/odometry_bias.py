"""Is a log's odometry biased?  Its relations' NEES under a random-walk model, and a calibration.

The motion model (:class:`slam.models.motion.MotionNoiseConfig`) is a random walk: the
variance of a chain of odometry steps grows with the distance travelled and the angle turned,
and nothing else.  An odometry with a persistent error (wheels of slightly different size, a
wrong wheel base, a miscalibrated gyro) errs the same way step after step, so its error grows
faster than the model says.  Against a log's relations this shows as a NEES that rises with the
relation's length: about 3 over relations of a few seconds, far above it over minutes.

:func:`odometry_relations_nees` computes each relation's NEES of the raw odometry under a given
noise model (the chained covariance, exact to first order, :func:`slam.lines.transform.
compose_chain`), optionally with the odometry calibrated by :class:`OdometryCalibration`
(translation scale, turn gain, heading drift per metre, applied to every step).
:func:`fit_odometry_calibration` fits the calibration to a subset of the relations (e.g. the
short ones) by robust least squares on the whitened errors.  If a calibration fitted on the
short relations makes the long ones consistent too, the odometry's long-range error is a bias
that three numbers describe, which a random-walk model cannot represent.
``scripts/odometry_bias.py`` prints both for a log.

:func:`relations_frame_offset` applies the same lever-arm fit to any trajectory (a run's, a
chain of scan matches): where the frame the relations relate sits in the trajectory's frame,
with its spread over bootstrap resamples (``scripts/relations_frame.py --lever-arm``,
``scripts/scan_match_consistency.py --lever-arm``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from slam.errors import EvaluationError
from slam.evaluation.timestamps import match_timestamps
from slam.geometry import adjoint_pose2, pose_between, pose_inverse, pose_log
from slam.lines.transform import compose_chain
from slam.models.motion import MotionNoiseConfig, OdometryCalibration

__all__ = [
    "FrameOffset",
    "OdometryCalibration",
    "RelationPairs",
    "fit_odometry_calibration",
    "odometry_relations_nees",
    "relation_pairs",
    "relations_frame_offset",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


@dataclass(frozen=True)
class RelationPairs:
    """Relations matched to the odometry's poses.

    Attributes
    ----------
    first, second : ndarray of int, shape (m,)
        Indices of the two poses of each relation in the odometry (``first < second``).
    poses : ndarray, shape (m, 3)
        The relation: the pose at ``second`` in the frame of the pose at ``first``.
    duration_s : ndarray, shape (m,)
        Time between the two poses.
    """

    first: IntArray
    second: IntArray
    poses: FloatArray
    duration_s: FloatArray


def relation_pairs(
    timestamps: FloatArray,
    t1: FloatArray,
    t2: FloatArray,
    poses: FloatArray,
    tolerance_s: float = 1e-3,
) -> RelationPairs:
    """Match relations ``(t1, t2, poses)`` to odometry stamps within ``tolerance_s``.

    ``timestamps`` are the odometry's, in its order (a log's file order; stamps that go back in
    time are matched too).  Relations whose stamps have no odometry pose within the tolerance
    are left out; a relation whose second pose comes first in that order is inverted.

    Raises
    ------
    EvaluationError
        No relation matches.
    """
    t = np.asarray(timestamps, dtype=float)
    if t.shape[0] < 2:
        raise EvaluationError("fewer than two odometry poses")
    t1, t2 = np.asarray(t1, float), np.asarray(t2, float)
    a, found_a = match_timestamps(t1, t, tolerance_s)
    b, found_b = match_timestamps(t2, t, tolerance_s)
    ok = found_a & found_b & (a != b)
    if not np.any(ok):
        raise EvaluationError("no relation has both of its stamps in the odometry")
    a, b, p = a[ok], b[ok], np.asarray(poses, float)[ok]
    back = a > b
    p = np.where(back[:, None], pose_inverse(p), p)
    return RelationPairs(
        np.asarray(np.where(back, b, a), np.intp),
        np.asarray(np.where(back, a, b), np.intp),
        p,
        np.abs(t2 - t1)[ok],
    )


def _whitened_errors(
    odometry: FloatArray,
    pairs: RelationPairs,
    noise: MotionNoiseConfig,
    calibration: OdometryCalibration,
) -> FloatArray:
    steps = pose_between(odometry[:-1], odometry[1:])
    C = noise.covariance(steps)
    poses, _ = compose_chain(calibration.apply(steps), C)
    # world-frame sums of the steps' covariances; a relation's covariance in its end frame
    Ad = adjoint_pose2(poses[1:])
    S = np.concatenate([np.zeros((1, 3, 3)), np.cumsum(Ad @ C @ np.swapaxes(Ad, 1, 2), axis=0)])
    i, j = pairs.first, pairs.second
    xi = pose_log(pose_between(pairs.poses, pose_between(poses[i], poses[j])))
    Aj = np.linalg.inv(adjoint_pose2(poses[j]))
    P = Aj @ (S[j] - S[i]) @ np.swapaxes(Aj, 1, 2)
    P = 0.5 * (P + np.swapaxes(P, 1, 2))
    # a chain the model leaves no error in some direction (a turn on the spot with no
    # translation noise per radian and no floor), or one lost to rounding in the sums
    scale = np.maximum(np.abs(S[j]).max(axis=(1, 2)), np.finfo(float).tiny)
    singular = np.linalg.eigvalsh(P)[:, 0] <= 1e-12 * scale
    if np.any(singular):
        k = int(np.flatnonzero(singular)[0])
        raise EvaluationError(
            f"the noise model gives {int(singular.sum())} relations no error in some "
            f"direction (the first between odometry poses {int(i[k])} and {int(j[k])}): "
            "give it a floor (sigma_xy_min_m, sigma_theta_min_rad) or noise per radian turned"
        )
    L = np.linalg.cholesky(P)
    return np.asarray(np.linalg.solve(L, xi[..., None])[..., 0], dtype=np.float64)


def odometry_relations_nees(
    odometry: FloatArray,
    pairs: RelationPairs,
    noise: MotionNoiseConfig,
    calibration: OdometryCalibration | None = None,
) -> FloatArray:
    """The NEES (3 dof) of each relation's raw-odometry error under ``noise``.

    Parameters
    ----------
    odometry : ndarray, shape (N, 3)
        The odometry's pose at every stamp, in order.
    pairs : RelationPairs
        The relations, matched to those poses (:func:`relation_pairs`).
    noise : MotionNoiseConfig
        The model of every step (its floors apply per step, so they count the steps).
    calibration : OdometryCalibration, optional
        Applied to every step first.
    """
    z = _whitened_errors(odometry, pairs, noise, calibration or OdometryCalibration())
    return np.asarray(np.sum(z**2, axis=1))


def fit_odometry_calibration(
    odometry: FloatArray,
    pairs: RelationPairs,
    noise: MotionNoiseConfig,
    use: NDArray[np.bool_] | None = None,
    parameters: Literal["bias", "mounting"] = "bias",
) -> OdometryCalibration:
    """The calibration that best explains the relations ``use`` (default all) under ``noise``.

    Robust least squares (``soft_l1`` at 3 σ) on the whitened errors, from no calibration.
    ``parameters``: the translation scale, turn gain and heading drift (``"bias"``), or where
    the laser sits in the frame whose motion the odometry reports (``"mounting"``: the
    calibration's ``mount_x_m``, ``mount_y_m``; the others zero).
    """
    if parameters not in ("bias", "mounting"):
        raise EvaluationError(f"parameters must be bias or mounting, got {parameters!r}")
    sel = np.ones(pairs.first.shape[0], bool) if use is None else np.asarray(use, bool)
    if np.count_nonzero(sel) < 3:
        raise EvaluationError("fewer than 3 relations to fit an odometry calibration to")
    sub = RelationPairs(
        pairs.first[sel], pairs.second[sel], pairs.poses[sel], pairs.duration_s[sel]
    )

    def calibration(p: FloatArray) -> OdometryCalibration:
        if parameters == "mounting":
            return OdometryCalibration(mount_x_m=float(p[0]), mount_y_m=float(p[1]))
        return OdometryCalibration(float(p[0]), float(p[1]), float(p[2]))

    def residuals(p: FloatArray) -> FloatArray:
        return _whitened_errors(odometry, sub, noise, calibration(p)).ravel()

    n = 2 if parameters == "mounting" else 3
    fit = least_squares(residuals, np.zeros(n), loss="soft_l1", f_scale=3.0)
    return calibration(fit.x)


@dataclass(frozen=True)
class FrameOffset:
    """Where the relations' frame sits in a trajectory's frame (:func:`relations_frame_offset`).

    Attributes
    ----------
    x_m, y_m : float
        The offset (m) along and across the trajectory frame's x axis.
    sd_x_m, sd_y_m : float
        Their standard deviations over the bootstrap resamples.
    relations : int
        How many relations the fit used.
    """

    x_m: float
    y_m: float
    sd_x_m: float
    sd_y_m: float
    relations: int


def relations_frame_offset(
    timestamps: FloatArray,
    poses: FloatArray,
    t1: FloatArray,
    t2: FloatArray,
    relation_poses: FloatArray,
    short_s: float = 10.0,
    resamples: int = 50,
    seed: int = 0,
    tolerance_s: float = 1e-3,
) -> FrameOffset:
    """Where the frame the relations relate sits in the frame of the trajectory ``poses``.

    The lever arm ``m = (x, y)`` with ``relation ≈ M⁻¹ · (the trajectory's relative pose) · M``,
    ``M = (x, y, 0)``, fitted to the relations shorter than ``short_s`` seconds as
    :func:`fit_odometry_calibration` fits a mounting (the trajectory in place of the odometry,
    the default motion model as the weights): a frame ``m`` away moves sideways by
    ``(R(θ) − I) m`` on every turn ``θ``, so the turns carry the information, straight
    relations none.  Its spread: the same fit on ``resamples`` bootstrap resamples of those
    relations (drawn with replacement, ``seed``).

    Parameters
    ----------
    timestamps : ndarray, shape (N,)
    poses : ndarray, shape (N, 3)
        The trajectory, in time order.
    t1, t2 : ndarray, shape (m,)
        The relations' time stamps.
    relation_poses : ndarray, shape (m, 3)
        The relations (the pose at ``t2`` in the frame at ``t1``).
    short_s : float
        Only relations shorter than this (s) are used.
    resamples : int
        Bootstrap resamples of the spread (at least 2).
    seed : int
    tolerance_s : float
        How far a relation's stamp may lie from the trajectory's (s).

    Raises
    ------
    EvaluationError
        Fewer than 3 relations shorter than ``short_s`` match the trajectory's stamps.
    """
    if resamples < 2:
        raise EvaluationError(f"resamples must be at least 2, got {resamples}")
    pairs = relation_pairs(timestamps, t1, t2, relation_poses, tolerance_s)
    rows = np.flatnonzero(pairs.duration_s < short_s)
    if rows.size < 3:
        raise EvaluationError(
            f"{rows.size} relations shorter than {short_s:g} s match the trajectory: "
            "at least 3 are needed to fit a frame offset"
        )
    noise = MotionNoiseConfig()

    def fit(k: IntArray) -> tuple[float, float]:
        sub = RelationPairs(pairs.first[k], pairs.second[k], pairs.poses[k], pairs.duration_s[k])
        c = fit_odometry_calibration(poses, sub, noise, parameters="mounting")
        return c.mount_x_m, c.mount_y_m

    x, y = fit(rows)
    rng = np.random.default_rng(seed)
    draws = np.array([fit(rng.choice(rows, rows.size)) for _ in range(resamples)])
    sd = draws.std(axis=0)
    return FrameOffset(float(x), float(y), float(sd[0]), float(sd[1]), int(rows.size))
