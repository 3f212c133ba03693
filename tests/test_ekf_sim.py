"""EKF-SLAM on a simulated corridor loop (line-level simulator): accuracy and NEES."""

from __future__ import annotations

import numpy as np
from filterpy.stats import NEES
from scipy.stats import chi2

from slam.ekf import EkfConfig, EkfSlam
from slam.ekf.conventions import cov_tangent_to_state
from slam.evaluation import nees_bounds, pose_nees_values
from slam.experiments.linesim import (
    SIM_ODOMETRY,
    corridor_loop_world,
    loop_trajectory,
    simulate_line_run,
)
from slam.geometry import wrap_angle


def run_ekf(seed, config=None):
    world = corridor_loop_world()
    truth = loop_trajectory(loops=1.0)
    run = simulate_line_run(world, truth, seed=seed)
    # the simulator's odometry model, and its fit covariances are exact: no model-error floor
    ekf = EkfSlam(config or EkfConfig(odometry=SIM_ODOMETRY, line_sigma_extra=(0.0, 0.0)))
    for scan, lines in zip(run.scans, run.lines, strict=True):
        ekf.add_scan(scan, lines)
    odom = np.array([s.pose_odom_laser for s in run.scans])
    return ekf.result(), truth, odom


def test_ekf_on_a_simulated_loop_beats_odometry_and_is_consistent():
    n_runs = 6
    nees = []
    for seed in range(n_runs):
        res, truth, odom = run_ekf(seed)
        err = np.linalg.norm(res.poses_world_laser[:, :2] - truth[:, :2], axis=1)
        err_odom = np.linalg.norm(odom[:, :2] - truth[:, :2], axis=1)
        rmse, rmse_odom = np.sqrt(np.mean(err**2)), np.sqrt(np.mean(err_odom**2))
        assert rmse < 0.03 and rmse < 0.1 * rmse_odom, (seed, rmse, rmse_odom)
        # the map: every wall has a landmark on it and every landmark is on a wall; pieces
        # of one wall seen apart are merged once they meet (at most one left unmerged here)
        walls = corridor_loop_world().lines_r_alpha
        lm = res.landmarks_r_alpha
        e = np.stack(
            [lm[:, None, 0] - walls[None, :, 0], wrap_angle(lm[:, None, 1] - walls[None, :, 1])],
            -1,
        )
        d2 = np.einsum("mwi,mij,mwj->mw", e, np.linalg.inv(res.landmark_covariances), e)
        # long walls: within the landmark's own covariance.  The 0.4 m stubs, seen from up to
        # 8 m and ~11 m from the world origin, end up over-confident (EKF linearisation with a
        # long lever in the (r, α) world parameterisation, see docs/ekf.md): absolute check.
        close = d2 < chi2.ppf(0.9999, 2)
        stub = np.arange(walls.shape[0]) >= 8
        close[:, stub] |= (np.abs(e[:, stub, 0]) < 0.25) & (np.abs(e[:, stub, 1]) < 0.03)
        assert np.all(close.any(axis=0)) and np.all(close.any(axis=1))
        assert 16 <= lm.shape[0] <= 17
        nees.append(pose_nees_values(res.poses_world_laser, res.pose_covariances, truth))
        # the tangent-space NEES equals filterpy's NEES of the additive error to first order
        e_add = truth - res.poses_world_laser
        e_add[:, 2] = wrap_angle(e_add[:, 2])
        P_add = cov_tangent_to_state(res.pose_covariances[1:], res.poses_world_laser[1:, 2])
        est = res.poses_world_laser[1:]
        ref = np.asarray(NEES(est + e_add[1:], est, P_add))  # angle error already wrapped
        np.testing.assert_allclose(nees[-1][1:], ref, rtol=0.02)
    anees = np.mean(np.array(nees)[:, 1:], axis=0)  # the first pose is anchored (P = 0)
    lo, hi = nees_bounds(3, n_runs, 0.95)
    inside = np.mean((anees > lo) & (anees < hi))
    assert inside > 0.8, (inside, anees.mean())
