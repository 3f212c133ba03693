"""The EKF and a batch least-squares solution (GTSAM, custom factors) agree on a tiny problem.

One pose with a prior, two mapped line landmarks with priors and a third new one, each measured
twice from that pose: the EKF updates with the first measurements of the mapped lines,
initialises the new one from its first measurement (augmentation, cross-covariances) and
updates with the second measurements; the batch solution optimises the same factors jointly.
With small noise there are no relinearisation effects to speak of, so means and covariances
must agree.
"""

from __future__ import annotations

import numpy as np
import pytest

from slam.association import AssociationConfig
from slam.ekf import EkfConfig, EkfSlam
from slam.ekf.conventions import cov_state_to_tangent
from slam.geometry import line_residual, predict_line_measurement

# the overlap test off (landmarks set without seen extents)
NO_OVERLAP_TEST = AssociationConfig(overlap_margin_m=1e9)

gtsam = pytest.importorskip("gtsam")


def normalised_difference(cov_a, cov_b):
    """Largest eigenvalue of |B^{-1/2} (A - B) B^{-1/2}|: relative error in every direction."""
    L = np.linalg.cholesky(cov_b)
    Li = np.linalg.inv(L)
    return float(np.max(np.abs(np.linalg.eigvalsh(Li @ (cov_a - cov_b) @ Li.T))))


def line_factor(key_pose, key_lm, z, R):
    noise = gtsam.noiseModel.Gaussian.Covariance(R)

    def error(this, values, jacobians):
        pose = values.atPose2(this.keys()[0])
        lm = np.asarray(values.atPoint2(this.keys()[1]), dtype=float)
        p = np.array([pose.x(), pose.y(), pose.theta()])
        z_pred, H_x, H_l = predict_line_measurement(lm, p)
        res, sign = line_residual(z_pred, z)
        if jacobians is not None:
            H_x, H_l = H_x.copy(), H_l.copy()
            H_x[0] *= sign
            H_l[0] *= sign
            jacobians[0] = H_x
            jacobians[1] = H_l
        return res

    return gtsam.CustomFactor(noise, [key_pose, key_lm], error)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_ekf_equals_batch_on_one_pose_and_three_landmarks(seed):
    rng = np.random.default_rng(100 + seed)
    pose0 = np.array([1.0, -0.5, 0.7])
    P0 = np.diag([0.02**2, 0.02**2, 0.01**2])
    pose_true = pose0 + rng.multivariate_normal(np.zeros(3), P0)
    lms_true = np.array([[3.0, 0.2], [2.0, 2.1], [4.0, -1.9]])
    R = np.array(
        [[[1e-4, 2e-6], [2e-6, 4e-5]], [[4e-4, -1e-5], [-1e-5, 1e-4]], [[2e-4, 0], [0, 9e-5]]]
    )
    z_true, _, _ = predict_line_measurement(lms_true, pose_true)
    z1 = z_true + np.stack([rng.multivariate_normal(np.zeros(2), R[i]) for i in range(3)])
    z2 = z_true + np.stack([rng.multivariate_normal(np.zeros(2), R[i]) for i in range(3)])

    lm_prior = lms_true[:2] + rng.normal(0.0, 0.02, (2, 2))
    P_lm = np.array([[0.02**2, 0.0], [0.0, 0.01**2]])

    ekf = EkfSlam(EkfConfig(association=NO_OVERLAP_TEST))
    x0 = np.concatenate([pose0, lm_prior.ravel()])
    ekf.set_state(x0, np.diag(np.r_[np.diag(P0), np.diag(P_lm), np.diag(P_lm)]))
    ekf.update(np.arange(2), z1[:2], R[:2])
    ekf.add_landmarks(z1[2:], R[2:], np.zeros((1, 2, 2)))
    ekf.update(np.arange(3), z2, R)

    X = gtsam.symbol("x", 0)
    L = [gtsam.symbol("l", i) for i in range(3)]
    graph = gtsam.NonlinearFactorGraph()
    prior_cov = cov_state_to_tangent(P0, pose0[2])
    graph.add(
        gtsam.PriorFactorPose2(
            X, gtsam.Pose2(*pose0), gtsam.noiseModel.Gaussian.Covariance(prior_cov)
        )
    )
    for i in range(2):
        graph.add(
            gtsam.PriorFactorPoint2(
                L[i], gtsam.Point2(*lm_prior[i]), gtsam.noiseModel.Gaussian.Covariance(P_lm)
            )
        )
    for i in range(3):
        graph.add(line_factor(X, L[i], z1[i], R[i]))
        graph.add(line_factor(X, L[i], z2[i], R[i]))
    init = gtsam.Values()
    init.insert(X, gtsam.Pose2(*pose0))
    for i in range(3):
        init.insert(L[i], gtsam.Point2(*lms_true[i] + 0.01))
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(1e-12)
    params.setAbsoluteErrorTol(1e-15)
    sol = gtsam.LevenbergMarquardtOptimizer(graph, init, params).optimize()
    marg = gtsam.Marginals(graph, sol)

    p = sol.atPose2(X)
    pose_batch = np.array([p.x(), p.y(), p.theta()])
    cov_pose_batch = marg.marginalCovariance(X)
    cov_pose_ekf = ekf.pose_covariance
    sig = np.sqrt(np.diag(cov_pose_batch))
    # means agree to a small fraction of a standard deviation
    assert np.all(np.abs(ekf.x[:3] - pose_batch) / sig < 0.02), (ekf.x[:3] - pose_batch) / sig
    assert normalised_difference(cov_pose_ekf, cov_pose_batch) < 0.02
    for i in range(3):
        lm_b = np.asarray(sol.atPoint2(L[i]))
        cov_b = marg.marginalCovariance(L[i])
        s_l = np.sqrt(np.diag(cov_b))
        assert np.all(np.abs(ekf.x[3 + 2 * i : 5 + 2 * i] - lm_b) / s_l < 0.02)
        P_l = ekf.P[3 + 2 * i : 5 + 2 * i, 3 + 2 * i : 5 + 2 * i]
        assert normalised_difference(P_l, cov_b) < 0.02
    # and the batch solution is not trivially the EKF's prior: the second scan moved it
    assert np.linalg.norm((pose_batch - pose0) / np.sqrt(np.diag(P0))) > 0.3
    assert np.all(np.diag(cov_pose_batch) < 0.9 * np.diag(cov_state_to_tangent(P0, pose0[2])))
