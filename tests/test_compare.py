"""The comparison's pieces: variant catalogue and sources, the one evaluation of a variant."""

from __future__ import annotations

import numpy as np
import pytest

from slam.errors import ConfigError
from slam.experiments.compare import run_compare
from slam.experiments.estimators import EstimateOutput
from slam.experiments.tasks import evaluate_variant
from slam.experiments.variants import (
    GRAPH_BATCH_BUDGET_S,
    DataSpec,
    Variant,
    default_variants,
    parse_source,
    parse_variants,
)
from slam.geometry import pose_compose, pose_exp, pose_inverse
from slam.io import Trajectory, relations_from_trajectory


def test_sources_name_a_simulated_world_or_a_log():
    assert parse_source("sim:corridor_loop") == DataSpec("sim", "corridor_loop", 1.0, 0)
    assert parse_source("sim:corridor_loop", seed=5).seed == 5
    spec = parse_source("sim:grid2x2:0.5:3", seed=5)
    assert spec == DataSpec("sim", "grid2x2", 0.5, 3) and spec.label == "sim:grid2x2:0.5:3"
    assert parse_source("sim:corridor_loop::7") == DataSpec("sim", "corridor_loop", 1.0, 7)
    assert parse_source("datasets/sim/demo/log.clf").label == "demo"
    assert parse_source("logs/intel.clf").label == "intel"
    assert (
        parse_source("intel") == DataSpec("log", "intel") and parse_source("intel").label == "intel"
    )
    with pytest.raises(ConfigError, match="bad simulated source"):
        parse_source("sim:corridor_loop:two")
    with pytest.raises(ConfigError, match="unknown simulated world"):
        parse_source("sim:moon")


def test_variants_from_a_user_list_and_the_default_catalogue():
    chosen = parse_variants(" ekf=ekf-nn, flat=graph-isam2/unweighted,,odometry ")
    assert chosen == (
        Variant("ekf", "ekf-nn"),
        Variant("flat", "graph-isam2", weighted=False),
        Variant("odometry", "odometry"),
    )
    with pytest.raises(ConfigError, match="unknown estimator"):
        parse_variants("a=kalman")
    on_logs = {v.name: v for v in default_variants(simulated=False)}
    on_sim = {v.name: v for v in default_variants(simulated=True)}
    assert {"graph-isam2-unweighted", "ekf-unweighted"} <= set(on_logs)
    assert set(on_sim) == {n for n, v in on_logs.items() if v.weighted}
    assert on_logs["graph-batch"].time_budget_s == GRAPH_BATCH_BUDGET_S
    assert all(v.time_budget_s is None for n, v in on_logs.items() if n != "graph-batch")
    assert all(v.time_budget_s is None for v in on_sim.values())
    with pytest.raises(ConfigError, match="unique"):
        run_compare(DataSpec("sim", "corridor_loop"), (Variant("a", "ekf"), Variant("a", "ekf")))


def _estimate(rng, n=60):
    """Truth (a wiggly path), and an estimate off by tangent noise of known covariance."""
    steps = np.column_stack([np.full(n, 0.3), np.zeros(n), rng.normal(0.0, 0.2, n)])
    truth = np.zeros((n, 3))
    for k in range(1, n):
        truth[k] = pose_compose(truth[k - 1], steps[k])
    cov = np.tile(np.diag([1e-4, 1e-4, 1e-5]), (n, 1, 1))
    xi = rng.normal(size=(n, 3)) * np.sqrt([1e-4, 1e-4, 1e-5])
    poses = pose_compose(truth, pose_inverse(pose_exp(xi)))
    poses[0], cov[0] = truth[0], 0.0  # the anchored first pose: exact, no covariance
    stamps = 100.0 + 0.1 * np.arange(n)
    est = EstimateOutput("ekf", stamps, poses, cov, np.full(n, 1e-3), np.zeros((0, 2)))
    return est, Trajectory(stamps, truth)


def test_one_variant_is_evaluated_against_every_reference_it_has(rng):
    est, truth = _estimate(rng)
    rel = relations_from_trajectory(truth.timestamps, truth.poses, [[0, 10], [5, 30], [20, 59]])
    facts = {"runtime_s": 1.0, "scans": 60}
    out = evaluate_variant(Variant("v", "ekf"), est, facts, truth, rel, started_at_truth=True)
    m = out.metrics
    assert list(m)[:2] == ["runtime_s", "scans"] and facts == {"runtime_s": 1.0, "scans": 60}
    # relations: three used, errors per relation, abscissa the first pose's scan
    assert m["relations_used"] == m["relations_total"] == 3
    np.testing.assert_array_equal(out.rel_scan, [0, 5, 20])
    assert out.rel_err_m is not None and m["rel_trans_mean_m"] == pytest.approx(
        np.mean(out.rel_err_m)
    )
    # ground truth: ATE after alignment, per-scan errors, unaligned means, NEES ~ 3 dof
    assert out.pos_err_m is not None and out.pos_err_m.shape == (60,)
    assert m["ate_rmse_m"] == pytest.approx(np.sqrt(np.mean(out.pos_err_m**2)))
    assert 0.005 < m["ate_rmse_m"] < 0.03 and m["pos_err_mean_m"] > 0.0
    assert m["rot_err_mean_deg"] > 0.0
    assert out.nees is not None and np.isnan(out.nees[0]) and np.all(np.isfinite(out.nees[1:]))
    assert m["nees_mean"] == pytest.approx(np.mean(out.nees[1:])) and 1.5 < m["nees_mean"] < 5.0


def test_references_missing_or_partial_leave_their_metrics_out(rng):
    est, truth = _estimate(rng)
    only_facts = evaluate_variant(Variant("v", "ekf"), est, {}, None, None, started_at_truth=False)
    assert only_facts.metrics == {} and only_facts.pos_err_m is None and only_facts.nees is None
    # a log's ground truth: no unaligned errors (the estimate starts where its odometry does);
    # a ground truth missing two scans leaves them undefined
    partial = Trajectory(np.delete(truth.timestamps, [3, 4]), np.delete(truth.poses, [3, 4], 0))
    out = evaluate_variant(Variant("v", "ekf"), est, {}, partial, None, started_at_truth=False)
    assert "pos_err_mean_m" not in out.metrics and "ate_rmse_m" in out.metrics
    assert out.pos_err_m is not None and out.nees is not None
    np.testing.assert_array_equal(np.flatnonzero(np.isnan(out.pos_err_m)), [3, 4])
    np.testing.assert_array_equal(np.flatnonzero(np.isnan(out.nees)), [0, 3, 4])
    # relations that no estimated pose matches: the error is reported, not raised
    far = relations_from_trajectory(truth.timestamps + 1e3, truth.poses, [[0, 10]])
    out = evaluate_variant(Variant("v", "ekf"), est, {}, None, far, started_at_truth=False)
    assert "relations_error" in out.metrics and out.rel_err_m is None
