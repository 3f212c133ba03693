"""Synthetic line-SLAM problems with known truth (tests and ``scripts/bench_graph.py``).

A robot drives a smooth random path; landmark ``j`` is a line placed near the pose that first
sees it; every pose measures ``lines_per_pose`` landmarks from a sliding window, with Gaussian
noise of a known (correlated) covariance; odometry is the true relative pose perturbed on the
right by noise of the :class:`~slam.models.motion.MotionNoiseConfig` covariance.  The initial
estimate is dead reckoning, with each landmark initialised from its first measurement.

All randomness comes from one seeded generator and is vectorised.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from linefit.line import normal_form
from slam.geometry import (
    line_to_parent,
    pose_between,
    pose_compose,
    pose_exp,
    predict_line_measurement,
)
from slam.graph.problem import LineGraph
from slam.models.motion import MotionNoiseConfig

__all__ = ["SYNTHETIC_MOTION", "SyntheticProblem", "synthetic_problem"]

FloatArray = NDArray[np.float64]

SYNTHETIC_MOTION = MotionNoiseConfig(sigma_theta_per_m=0.02, sigma_theta_per_rad=0.05)
"""The synthetic problems' odometry noise, fixed here (equal to the library's defaults) so that
the synthetic benchmarks and tests do not move if the defaults are changed for real logs."""


@dataclass(frozen=True, eq=False)
class SyntheticProblem:
    """A :class:`LineGraph` with its ground truth.

    Attributes
    ----------
    graph : LineGraph
        Factors and the dead-reckoning initial estimate.
    poses_true : ndarray, shape (N, 3)
    landmarks_true : ndarray, shape (M, 2)
        World lines, signed ``(r, α)`` (the representative used to generate the data).
    """

    graph: LineGraph
    poses_true: FloatArray
    landmarks_true: FloatArray


def synthetic_problem(
    n_poses: int,
    lines_per_pose: int = 5,
    seed: int = 0,
    step_m: float = 0.3,
    sigma_r_m: float = 0.01,
    sigma_alpha_rad: float = 0.004,
    motion: MotionNoiseConfig | None = None,
    poses_per_landmark: int = 4,
    awkward: bool = True,
) -> SyntheticProblem:
    """Build a synthetic problem (see the module docstring).

    Parameters
    ----------
    n_poses : int
        Number of poses (>= 2).
    lines_per_pose : int
        Measurements per pose; pose ``i`` sees landmarks ``i // poses_per_landmark + k``,
        ``k < lines_per_pose``, so each landmark is seen from about
        ``lines_per_pose · poses_per_landmark`` consecutive poses.
    seed : int
    step_m : float
        Distance between consecutive poses.
    sigma_r_m, sigma_alpha_rad : float
        Measurement noise (each measurement gets a random correlation in [−0.5, 0.5]).
    motion : MotionNoiseConfig, optional
        Odometry noise (default: :data:`SYNTHETIC_MOTION`, a well-calibrated odometry).
    poses_per_landmark : int
        See ``lines_per_pose``.
    awkward : bool
        Make landmark 0 pass through the world origin (``r = 0``) and landmark 1 have its
        normal at ``α ≈ π``.
    """
    rng = np.random.default_rng(seed)
    motion = motion or SYNTHETIC_MOTION
    if n_poses < 2:
        raise ValueError("n_poses must be >= 2")
    # true path: smooth random turns
    turn = np.cumsum(rng.normal(0.0, 0.15, n_poses - 1)) * 0.3
    rel_true = np.column_stack(
        [np.full(n_poses - 1, step_m), np.zeros(n_poses - 1), np.diff(np.r_[0.0, turn])]
    )
    poses = np.zeros((n_poses, 3))
    for i in range(1, n_poses):  # sequential by nature (one compose per pose)
        poses[i] = pose_compose(poses[i - 1], rel_true[i - 1])
    # landmarks anchored at the first pose that sees them
    n_lm = (n_poses - 1) // poses_per_landmark + lines_per_pose
    anchor = np.minimum(np.arange(n_lm) * poses_per_landmark, n_poses - 1)
    r_s = rng.uniform(1.0, 5.0, n_lm)
    a_s = rng.uniform(-np.pi, np.pi, n_lm)
    lines_anchor = np.column_stack([r_s, a_s, np.zeros(n_lm)])
    lm_true = line_to_parent(lines_anchor, poses[anchor], normal_form=False)[0][:, :2]
    if awkward and n_lm >= 2:
        lm_true[0] = [0.0, 0.3 + poses[0, 2]]  # through the world origin
        lm_true[1, 1] = np.pi - 1e-7  # normal at +π
    # measurements
    pose_idx = np.repeat(np.arange(n_poses), lines_per_pose)
    lm_idx = pose_idx // poses_per_landmark + np.tile(np.arange(lines_per_pose), n_poses)
    F = pose_idx.shape[0]
    rho = rng.uniform(-0.5, 0.5, F)
    sr = sigma_r_m * rng.uniform(0.5, 2.0, F)
    sa = sigma_alpha_rad * rng.uniform(0.5, 2.0, F)
    cov = np.zeros((F, 2, 2))
    cov[:, 0, 0] = sr**2
    cov[:, 1, 1] = sa**2
    cov[:, 0, 1] = cov[:, 1, 0] = rho * sr * sa
    z_true, _, _ = predict_line_measurement(lm_true[lm_idx], poses[pose_idx])
    noise = np.einsum("fij,fj->fi", np.linalg.cholesky(cov), rng.standard_normal((F, 2)))
    r_m, a_m, _ = normal_form(z_true[:, 0] + noise[:, 0], z_true[:, 1] + noise[:, 1])
    z = np.column_stack([r_m, a_m])
    foot = z[:, :1] * np.column_stack([np.cos(z[:, 1]), np.sin(z[:, 1])])
    tang = np.column_stack([-np.sin(z[:, 1]), np.cos(z[:, 1])])
    endpoints = np.stack([foot - tang, foot + tang], axis=1)
    # odometry
    rel = pose_between(poses[:-1], poses[1:])
    odo_cov = motion.covariance(rel)
    odo_noise = np.einsum(
        "eij,ej->ei", np.linalg.cholesky(odo_cov), rng.standard_normal((n_poses - 1, 3))
    )
    odo = pose_compose(rel, pose_exp(odo_noise))
    # dead reckoning and landmark initialisation
    dr = np.zeros((n_poses, 3))
    dr[0] = poses[0]
    for i in range(1, n_poses):
        dr[i] = pose_compose(dr[i - 1], odo[i - 1])
    first = np.full(n_lm, -1)
    order = np.arange(F)[::-1]
    first[lm_idx[order]] = order  # last write wins: the first factor of each landmark
    z_first = np.column_stack([z[first], np.zeros(n_lm)])
    lm_init = line_to_parent(z_first, dr[pose_idx[first]], normal_form=False)[0][:, :2]
    ep_first = endpoints[first].mean(axis=1)
    anchors = pose_compose(dr[pose_idx[first]], np.column_stack([ep_first, np.zeros(n_lm)]))[:, :2]

    graph = LineGraph()
    for p in dr:
        graph.add_pose(p)
    graph.set_prior(poses[0], np.diag([1e-8, 1e-8, 1e-10]))
    graph.add_landmarks(lm_init, anchors)
    for i in range(n_poses - 1):
        graph.add_odometry(i, i + 1, odo[i], odo_cov[i])
    for i in range(n_poses):
        sl = slice(i * lines_per_pose, (i + 1) * lines_per_pose)
        graph.add_line_factors(i, lm_idx[sl], z[sl], cov[sl], endpoints[sl])
    return SyntheticProblem(graph=graph, poses_true=poses, landmarks_true=lm_true)
