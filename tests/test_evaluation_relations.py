"""Relations metric: known answers on constructed data, Cartographer's definitions."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from slam.errors import EvaluationError
from slam.evaluation import (
    match_timestamps,
    relation_errors,
    relations_metric,
    relations_within,
)
from slam.geometry import pose_compose, wrap_angle
from slam.io import Relations, Trajectory, relations_from_trajectory


def random_poses(rng, n, spread=10.0):
    return np.column_stack(
        [rng.normal(0, spread, n), rng.normal(0, spread, n), rng.uniform(-np.pi, np.pi, n)]
    )


def test_error_of_a_left_perturbed_relation_is_the_perturbation(rng):
    m = 400
    expected = random_poses(rng, m)
    delta = random_poses(rng, m, spread=0.5)
    pose_1 = random_poses(rng, m)
    # pose_1⁻¹·pose_2 = delta·expected  ⇒  error = delta
    pose_2 = pose_compose(pose_1, pose_compose(delta, expected))
    rel = Relations.planar(np.arange(m), np.arange(m) + 0.5, expected)
    trans, angle = relation_errors(pose_1, pose_2, rel)
    np.testing.assert_allclose(trans, np.hypot(delta[:, 0], delta[:, 1]), atol=1e-9)
    np.testing.assert_allclose(angle, np.abs(wrap_angle(delta[:, 2])), atol=1e-9)


def test_three_d_relation_matches_a_rigid_transform_library(rng):
    m = 50
    pose_1, pose_2 = random_poses(rng, m), random_poses(rng, m)
    xyz = rng.normal(0, 3, (m, 3))
    rpy = rng.uniform(-0.3, 0.3, (m, 3))
    rel = Relations(
        np.zeros(m),
        np.ones(m),
        np.column_stack([xyz[:, :2], rpy[:, 2]]),
        xyz[:, 2],
        rpy[:, 0],
        rpy[:, 1],
        np.zeros(m, np.int64),
    )
    trans, angle = relation_errors(pose_1, pose_2, rel)
    for k in range(m):
        r1 = Rotation.from_euler("z", pose_1[k, 2])
        r2 = Rotation.from_euler("z", pose_2[k, 2])
        t1 = np.array([pose_1[k, 0], pose_1[k, 1], 0.0])
        t2 = np.array([pose_2[k, 0], pose_2[k, 1], 0.0])
        r_rel, t_rel = r1.inv() * r2, r1.inv().apply(t2 - t1)
        r_exp = Rotation.from_euler("ZYX", [rpy[k, 2], rpy[k, 1], rpy[k, 0]])
        r_err = r_rel * r_exp.inv()
        t_err = t_rel - r_err.apply(xyz[k])
        assert trans[k] == pytest.approx(np.linalg.norm(t_err), abs=1e-9)
        assert angle[k] == pytest.approx(r_err.magnitude(), abs=1e-9)


def test_metric_statistics_are_cartographers(rng):
    n = 300
    stamps = np.round(np.cumsum(rng.uniform(0.1, 0.5, n)), 6)
    truth = np.cumsum(random_poses(rng, n, 0.3), axis=0)
    pairs = rng.integers(0, n, (500, 2))
    relations = relations_from_trajectory(stamps, truth, pairs)
    zero = relations_metric(Trajectory(stamps, truth), relations)
    assert zero.abs_trans_m.mean < 1e-9 and zero.abs_rot_deg.mean < 1e-7
    noisy = truth + rng.normal(0, 0.05, truth.shape)
    metric = relations_metric(Trajectory(stamps, noisy), relations)
    t, a = metric.trans_errors_m, metric.rot_errors_deg
    assert metric.abs_trans_m.mean == pytest.approx(t.mean())
    assert metric.abs_trans_m.std == pytest.approx(t.std(ddof=1))
    assert metric.sqr_trans_m2.std == pytest.approx((t**2).std(ddof=1))
    assert metric.sqr_rot_deg2.mean == pytest.approx((a**2).mean())
    assert metric.n_used == 500 and metric.n_unmatched == 0
    d = metric.to_dict()
    assert d["abs_trans_m"]["std"] == metric.abs_trans_m.std and d["n_used"] == 500
    assert metric.cartographer_report().startswith("Abs translational error ")


def test_unmatched_relations_are_counted_and_fail_above_the_limit(rng):
    n = 200
    stamps = np.arange(n) * 0.1 + 5.0
    truth = np.cumsum(random_poses(rng, n, 0.3), axis=0)
    pairs = np.column_stack([np.arange(n - 1), np.arange(1, n)])
    relations = relations_from_trajectory(stamps, truth, pairs)
    keep = np.ones(n, bool)
    keep[[10]] = False  # 2 of 199 relations lose a stamp: 1 %
    metric = relations_metric(Trajectory(stamps[keep], truth[keep]), relations)
    assert metric.n_unmatched == 2 and metric.n_used == 197
    keep[[50, 90]] = False  # 6 of 199: 3 %
    with pytest.raises(EvaluationError, match="6 of 199 relations"):
        relations_metric(Trajectory(stamps[keep], truth[keep]), relations)
    metric = relations_metric(
        Trajectory(stamps[keep], truth[keep]), relations, max_unmatched_fraction=0.05
    )
    assert metric.n_unmatched == 6


def test_matching_works_for_unsorted_stamps_and_respects_tolerance(rng):
    stamps = rng.permutation(np.arange(100) * 0.01 + 1e9)
    idx, found = match_timestamps(stamps[[3, 70]] + 4e-6, stamps, 1e-5)
    assert found.all() and list(idx) == [3, 70]
    idx, found = match_timestamps(np.array([stamps[5] + 2e-5]), stamps, 1e-5)
    assert not found.any()


def test_relations_within_keeps_exactly_those_inside_a_partial_run(rng):
    # A run over the first 60 of 100 scans: relations with either stamp after scan 59 are left
    # out, the others kept in file order, and the metric then counts no unmatched relation.
    n = 100
    stamps = rng.permutation(np.arange(n) * 0.1 + 1000.0)  # any order, as Intel's
    poses = random_poses(rng, n)
    pairs = np.column_stack([rng.integers(0, n, 300), rng.integers(0, n, 300)])
    rel = relations_from_trajectory(stamps, poses, pairs)
    run = Trajectory.from_arrays(stamps[:60], poses[:60])
    inside = relations_within(rel, run.timestamps)
    keep = (pairs[:, 0] < 60) & (pairs[:, 1] < 60)
    assert len(inside) == int(keep.sum()) and 0 < len(inside) < len(rel)
    np.testing.assert_array_equal(inside.t1, rel.t1[keep])
    np.testing.assert_array_equal(inside.poses, rel.poses[keep])
    metric = relations_metric(run, inside)
    assert metric.n_unmatched == 0 and metric.abs_trans_m.mean < 1e-9
    with pytest.raises(EvaluationError):
        relations_metric(run, rel)  # the whole file would be a time stamp mistake


def test_evaluate_reports_where_the_relations_frame_sits(rng):
    """Relations of a frame 4 cm ahead of the trajectory's: ``evaluate_results`` finds it
    (within four bootstrap standard deviations) and writes it to ``metrics.json``; relations
    of the trajectory's own frame give about zero; with no short relations it says why."""
    from slam.evaluation.report import evaluate_results
    from slam.lines.transform import compose_chain

    n = 2000
    steps = np.column_stack([np.full(n, 0.05), np.zeros(n), 0.15 * np.sin(np.arange(n) / 25.0)])
    poses, _ = compose_chain(steps)
    t = np.arange(n + 1, dtype=float)
    trajectory = Trajectory(t, poses)
    first = rng.choice(n - 5, size=400, replace=False)
    for ahead in (0.04, 0.0):
        frame = pose_compose(poses, np.array([ahead, 0.0, 0.0]))
        rel = relations_from_trajectory(t, frame, np.column_stack([first, first + 5]))
        noisy = pose_compose(rel.poses, rng.normal(0.0, [0.004, 0.004, 0.002], rel.poses.shape))
        report = evaluate_results(trajectory, relations=Relations.planar(rel.t1, rel.t2, noisy))
        f = report.relations_frame
        assert f is not None and f.relations == 400
        assert abs(f.x_m - ahead) < 4 * f.sd_x_m + 1e-4 and abs(f.y_m) < 4 * f.sd_y_m + 1e-4
        assert report.to_dict()["relations_frame"]["x_m"] == f.x_m
        assert "relations' frame" in report.format_table()
    far = relations_from_trajectory(t, poses, np.column_stack([first, first + 5]))
    far = Relations.planar(far.t1 * 3.0, far.t2 * 3.0, far.poses)  # 15 s apart: none short
    report = evaluate_results(Trajectory(3.0 * t, poses), relations=far)
    assert report.relations_frame is None
    assert "at least 3" in report.to_dict()["relations_frame"]["skipped"]
