"""Experiment machinery: seeds, serial == parallel (Dask LocalCluster), Monte-Carlo NEES."""

from __future__ import annotations

import numpy as np
import pytest

from linefit.errors import ConfigError
from slam.config import RunConfig
from slam.evaluation import nees_bounds, pose_nees_values
from slam.experiments.consistency import ConsistencyConfig, run_consistency
from slam.experiments.estimators import run_estimator
from slam.experiments.linesim import matched_run_config, simulate_line_run, world_and_trajectory
from slam.experiments.parallel import map_tasks, task_seed


def _square(x: int) -> int:
    return x * x


def test_serial_map_keeps_order_and_reports_progress():
    seen = []
    assert map_tasks(_square, [3, 1, 2], progress=lambda d, t: seen.append((d, t))) == [9, 1, 4]
    assert seen == [(1, 3), (2, 3), (3, 3)]


def test_task_seeds_are_stable_and_distinct():
    seeds = [task_seed(7, i) for i in range(1000)]
    assert len(set(seeds)) == 1000
    assert seeds == [task_seed(7, i) for i in range(1000)]
    assert task_seed(7, 3) != task_seed(8, 3)
    assert all(0 <= s < 2**63 for s in seeds)


def test_odometry_only_is_consistent_and_the_ekf_beats_it():
    """Dead reckoning with the exact motion model must give NEES ≈ 3 (checks the machinery)."""
    cfg = ConsistencyConfig(n_runs=20, world="corridor_loop", loops=0.5, estimators=("odometry",))
    res = run_consistency(cfg).estimators["odometry"]
    lo, hi = nees_bounds(3, 20, 0.95)
    assert res.bounds == pytest.approx((lo, hi))
    assert res.fraction_inside >= 0.85, res.fraction_inside
    assert 2.4 < res.mean_anees < 3.6
    assert np.all(np.isnan(res.nees[:, 0]))  # the first pose is given exactly
    # the heading part alone is χ²(1): its average near 1, and never above the pose NEES
    # (a marginal of the quadratic form), defined exactly where the pose NEES is
    assert res.heading_bounds == pytest.approx(nees_bounds(1, 20, 0.95))
    assert 0.7 < res.mean_anees_heading < 1.3, res.mean_anees_heading
    ok = np.isfinite(res.nees)
    np.testing.assert_array_equal(np.isfinite(res.nees_heading), ok)
    assert np.all(res.nees_heading[ok] <= res.nees[ok] * (1.0 + 1e-12))
    assert np.mean(res.nees_heading[ok] < 0.5 * res.nees[ok]) > 0.3  # not the whole NEES


def test_serial_and_local_cluster_give_identical_results():
    cfg = ConsistencyConfig(
        n_runs=3, world="corridor_loop", loops=0.5, estimators=("ekf", "odometry")
    )
    serial = run_consistency(cfg, workers=1)
    parallel = run_consistency(cfg, workers=2)
    for name in cfg.estimators:
        a, b = serial.estimators[name], parallel.estimators[name]
        np.testing.assert_array_equal(a.nees, b.nees)
        np.testing.assert_array_equal(a.nees_heading, b.nees_heading)
        np.testing.assert_array_equal(a.pos_rmse_m, b.pos_rmse_m)
        np.testing.assert_array_equal(a.landmarks, b.landmarks)
    ekf, odo = serial.estimators["ekf"], serial.estimators["odometry"]
    assert np.all(ekf.pos_rmse_m < 0.2 * odo.pos_rmse_m)
    # runs differ from each other (distinct seeds), so equal arrays also prove task order
    assert len(set(serial.estimators["odometry"].pos_rmse_m.tolist())) == 3


def test_batch_graph_nees_is_that_of_its_smoothed_trajectory_and_lands_in_the_results():
    cfg = ConsistencyConfig(
        n_runs=1, world="corridor_loop", loops=0.4, estimators=("graph-batch", "odometry")
    )
    assert "graph-batch" in ConsistencyConfig().estimators  # part of the default study
    res = run_consistency(cfg)
    batch, odo = res.estimators["graph-batch"], res.estimators["odometry"]
    # the same run outside the study: its final trajectory and marginals give the same NEES
    world, truth = world_and_trajectory(cfg.world, cfg.loops)
    run = simulate_line_run(world, truth, cfg.linesim, seed=task_seed(cfg.seed, 0))
    rc = matched_run_config(RunConfig(), cfg.linesim)
    assert RunConfig().slam.line_pass_error == "estimated"
    assert rc.slam.line_pass_error == "off"  # the simulator's observations err independently
    est = run_estimator("graph-batch", run.scans, run.lines, rc, truth[0])
    assert est.pose_covariances is not None
    expected = pose_nees_values(est.poses_world_laser, est.pose_covariances, truth)
    np.testing.assert_array_equal(batch.nees[0], expected)
    assert np.all(np.isfinite(batch.nees[0]))  # the first pose's prior is tight, not exact
    assert 0.3 < batch.mean_anees < 15.0  # the order of 3 dof, not a unit mix-up
    assert batch.pos_rmse_m[0] < 0.1 * odo.pos_rmse_m[0]
    doc = res.to_dict()["estimators"]["graph-batch"]
    assert doc["mean_anees"] == pytest.approx(batch.mean_anees)
    assert doc["anees"] == pytest.approx(batch.anees.tolist())
    assert len(doc["anees"]) == truth.shape[0]


def test_bad_experiment_configuration_is_rejected():
    with pytest.raises(ConfigError, match="unknown estimator"):
        ConsistencyConfig(estimators=("kalman",))
    with pytest.raises(ConfigError, match="unknown simulated world"):
        ConsistencyConfig(world="moon")
    with pytest.raises(ConfigError):
        ConsistencyConfig(n_runs=0)
    with pytest.raises(ConfigError, match="Dask scheduler"):
        map_tasks(_square, [1], dask_address="tcp://127.0.0.1:9", connect_timeout_s=1.0)


def test_ekf_and_odometry_follow_the_graphs_laser_mounting_and_output_frame():
    """With ``slam.laser_odometry = "base"`` the EKF sees ``base odometry ∘ mounting`` and with
    ``output_frame = "base"`` reports base poses: dead reckoning then returns the base odometry
    itself, whatever the (wrong) logged laser poses say."""
    from dataclasses import replace

    from slam.config import RunConfig
    from slam.experiments.estimators import run_estimator
    from slam.geometry import pose_compose
    from slam.types import Scan

    rng = np.random.default_rng(4)
    base = np.cumsum(rng.normal([0.3, 0.0, 0.05], [0.05, 0.02, 0.1], (30, 3)), axis=0)
    scans = [
        Scan(
            index=k,
            timestamp=float(k),
            ranges=np.zeros(0),
            bearings=np.zeros(0),
            pose_odom_base=base[k],
            pose_odom_laser=base[k],  # the mounting is missing from the logged laser pose
        )
        for k in range(30)
    ]
    rc = RunConfig()
    mounted = replace(
        rc,
        scanner=replace(
            rc.scanner,
            pose_base_laser=(0.2, 0.05, 0.1),
            laser_odometry="base",
            output_frame="base",
        ),
    )
    out = run_estimator("odometry", scans, None, mounted, None)
    np.testing.assert_allclose(out.poses_world_laser, base, atol=1e-12)
    assert out.stats["frame"] == "base"
    laser_cfg = replace(mounted, scanner=replace(mounted.scanner, output_frame="laser"))
    laser = run_estimator("odometry", scans, None, laser_cfg, None).poses_world_laser
    # the laser poses are the base poses composed with the mounting (not the logged ones)
    expected = pose_compose(base, np.broadcast_to([0.2, 0.05, 0.1], base.shape))
    np.testing.assert_allclose(laser[:, :2], expected[:, :2], atol=1e-12)
    assert np.max(np.abs(laser[:, :2] - base[:, :2])) > 0.1
