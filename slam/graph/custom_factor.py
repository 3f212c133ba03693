"""Reference implementation of the line factor as a ``gtsam.CustomFactor``.

Slow (one Python callback per factor and linearisation, each copying the ``Values``; see
``scripts/bench_graph.py``) but written the way GTSAM's own Python examples write factors,
so that it can be read against the maths and checked against the vectorised fast path
(:mod:`slam.graph.factors`): the tests compare the two linearisations entry by entry and the
solutions of whole problems.

The pose is a ``gtsam.Pose2`` (laser in the world), the landmark a ``gtsam.Point2`` holding the
anchored ``(ρ, φ)`` (:mod:`slam.models.anchored`; the anchor is a constant of the factor); the
noise model is ``noiseModel.Gaussian.Covariance(R)``.
"""

from __future__ import annotations

import gtsam
import numpy as np
from numpy.typing import NDArray

from slam.geometry import line_residual, predict_line_measurement
from slam.models.anchored import anchored_jacobian, r_alpha_from_anchored

__all__ = ["line_custom_factor", "values_from_arrays"]

FloatArray = NDArray[np.float64]


def line_custom_factor(
    pose_key: int,
    landmark_key: int,
    anchor: FloatArray,
    z: FloatArray,
    cov: FloatArray,
    noise: gtsam.noiseModel.Base | None = None,
) -> gtsam.CustomFactor:
    """A line factor between ``pose_key`` (Pose2) and ``landmark_key`` (Point2 ``(ρ, φ)``).

    Parameters
    ----------
    pose_key, landmark_key : int
        GTSAM keys.
    anchor : ndarray, shape (2,)
        The landmark's anchor point.
    z : ndarray, shape (2,)
        Measured ``(r, α)`` in the laser frame.
    cov : ndarray, shape (2, 2)
        Its covariance.
    noise : gtsam.noiseModel.Base, optional
        Overrides the Gaussian noise model built from ``cov`` (e.g. a ``noiseModel.Robust``).

    Returns
    -------
    gtsam.CustomFactor
    """
    z_meas = np.asarray(z, dtype=float).copy()
    c = np.asarray(anchor, dtype=float).reshape(2).copy()
    model = noise if noise is not None else gtsam.noiseModel.Gaussian.Covariance(np.asarray(cov))

    def error(
        this: gtsam.CustomFactor, values: gtsam.Values, jacobians: list[FloatArray] | None
    ) -> FloatArray:
        pose = values.atPose2(this.keys()[0])
        v = np.asarray(values.atPoint2(this.keys()[1]), dtype=float)
        x = np.array([pose.x(), pose.y(), pose.theta()])
        z_pred, H_pose, H_lm = predict_line_measurement(r_alpha_from_anchored(v, c), x)
        e, sign = line_residual(z_pred, z_meas)
        if jacobians is not None:
            row = np.array([[float(sign)], [1.0]])
            jacobians[0] = H_pose * row
            jacobians[1] = (H_lm @ anchored_jacobian(v, c)) * row
        return np.asarray(e, dtype=float)

    return gtsam.CustomFactor(model, [pose_key, landmark_key], error)


def values_from_arrays(
    pose_keys: list[int],
    poses: FloatArray,
    landmark_keys: list[int],
    landmarks: FloatArray,
) -> gtsam.Values:
    """A ``gtsam.Values`` holding ``Pose2`` poses and ``Point2`` landmarks (anchored ``(ρ, φ)``)."""
    values = gtsam.Values()
    for key, p in zip(pose_keys, np.asarray(poses, dtype=float), strict=True):
        values.insert(key, gtsam.Pose2(float(p[0]), float(p[1]), float(p[2])))
    for key, lm in zip(landmark_keys, np.asarray(landmarks, dtype=float), strict=True):
        values.insert(key, gtsam.Point2(float(lm[0]), float(lm[1])))
    return values
