"""The relations' own scatter (three-cornered hat) and the relations NEES that allows for it."""

from __future__ import annotations

import numpy as np
import pytest
from test_relations_nees import _pairs, _relations, _synthetic_run

from slam.errors import EvaluationError
from slam.evaluation.reference_noise import relation_noise, three_cornered_hat
from slam.evaluation.relations_nees import relations_nees
from slam.geometry import pose_compose, pose_exp
from slam.graph.relative import RunCovariances
from slam.io.relations import Relations
from slam.io.trajectory import Trajectory


def test_three_cornered_hat_recovers_three_independent_noise_levels() -> None:
    """Reference, estimate a and estimate b with independent errors of known σ per component:
    each σ comes back within Monte-Carlo error (20,000 rows)."""
    rng = np.random.default_rng(11)
    m = 20_000
    s_ref, s_a, s_b = np.array([0.03, 0.01, 0.02]), np.array([0.005, 0.02, 0.01]), 0.015
    ref = rng.standard_normal((m, 3)) * s_ref
    a = rng.standard_normal((m, 3)) * s_a - ref  # errors against the reference
    b = rng.standard_normal((m, 3)) * s_b - ref
    v_ref, v_a, v_b = three_cornered_hat(a, b)
    np.testing.assert_allclose(np.sqrt(v_ref), s_ref, rtol=0.05)
    np.testing.assert_allclose(np.sqrt(v_a), s_a, rtol=0.08)
    np.testing.assert_allclose(np.sqrt(v_b), s_b, rtol=0.05)


def test_three_cornered_hat_finds_no_scatter_in_an_exact_reference() -> None:
    rng = np.random.default_rng(3)
    a = rng.standard_normal((5000, 2)) * 0.02
    b = rng.standard_normal((5000, 2)) * 0.01
    v_ref, _, _ = three_cornered_hat(a, b)
    assert np.all(np.abs(v_ref) < 0.05 * 0.01**2)


def test_three_cornered_hat_rejects_bad_shapes() -> None:
    with pytest.raises(EvaluationError, match="at least 3 rows"):
        three_cornered_hat(np.zeros((2, 3)), np.zeros((2, 3)))
    with pytest.raises(EvaluationError, match="one shape"):
        three_cornered_hat(np.zeros((5, 3)), np.zeros((5, 2)))


def _noisy(poses: np.ndarray, sigma: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    return np.asarray(pose_compose(poses, pose_exp(rng.standard_normal(poses.shape) * sigma)))


def test_relation_noise_on_a_walk_with_noisy_relations() -> None:
    """A random walk; relations between consecutive scans perturbed by a known σ; run and
    odometry each with their own pose noise: the relations' σ is recovered, and the relations
    that are the odometry's own motion are counted as coinciding."""
    rng = np.random.default_rng(5)
    n = 3001
    steps = np.column_stack(
        [np.full(n - 1, 0.2), rng.normal(0, 0.02, n - 1), rng.normal(0, 0.1, n - 1)]
    )
    truth = np.zeros((n, 3))
    for k in range(n - 1):
        truth[k + 1] = pose_compose(truth[k], steps[k])
    stamps = 100.0 + 0.5 * np.arange(n)
    pairs = np.column_stack([np.arange(n - 1), np.arange(1, n)])
    exact = _relations(truth, stamps, pairs)
    s_rel = np.array([0.02, 0.01, 0.005])
    noisy_rel = np.asarray(
        pose_compose(exact.poses, pose_exp(rng.standard_normal((n - 1, 3)) * s_rel))
    )
    odometry = Trajectory(stamps, _noisy(truth, np.array([0.004, 0.004, 0.002]), rng))
    # the first 100 relations are the odometry's own motion
    from slam.geometry import pose_between

    noisy_rel[:100] = pose_between(odometry.poses[:100], odometry.poses[1:101])
    relations = Relations(
        exact.t1, exact.t2, noisy_rel, exact.z, exact.roll, exact.pitch, exact.line_numbers
    )
    run = Trajectory(stamps, _noisy(truth, np.array([0.002, 0.002, 0.001]), rng))
    sub = relations.subset(np.arange(n - 1) >= 100)
    got = relation_noise(run, odometry, sub)
    assert got.n == n - 101
    np.testing.assert_allclose(np.sqrt(got.var_relations), s_rel, rtol=0.1)
    assert relation_noise(run, odometry, relations).odometry_coincides == 100
    long = Relations(
        exact.t1, exact.t1 + 20.0, noisy_rel, exact.z, exact.roll, exact.pitch, exact.line_numbers
    )
    with pytest.raises(EvaluationError, match="too few"):
        relation_noise(run, odometry, long)


def test_relations_nees_allows_for_the_relations_own_noise(tmp_path) -> None:
    """Solved synthetic graphs with exact covariances; relations perturbed by a known
    covariance R: the plain NEES is inflated, with R added it is about 3 again."""
    rng = np.random.default_rng(2)
    R = np.diag([0.03, 0.03, 0.01]) ** 2
    plain, allowed = [], []
    for seed in range(8):
        traj, truth, _, path = _synthetic_run(seed, tmp_path, 30)
        cov = RunCovariances.from_file(path)
        pairs = np.concatenate(list(_pairs(30).values()))
        rel = _relations(truth, traj.timestamps, pairs)
        w = rng.multivariate_normal(np.zeros(3), R, size=len(rel))
        rel = Relations(
            rel.t1,
            rel.t2,
            np.asarray(pose_compose(rel.poses, pose_exp(w))),
            rel.z,
            rel.roll,
            rel.pitch,
            rel.line_numbers,
        )
        plain.append(relations_nees(traj, rel, cov.relative_covariances).values)
        allowed.append(relations_nees(traj, rel, cov.relative_covariances, relations_cov=R).values)
    assert np.concatenate(plain).mean() > 5.0
    assert 2.6 < np.concatenate(allowed).mean() < 3.4


def test_evaluate_keeps_the_relations_nees_when_the_scatter_cannot_be_estimated(tmp_path) -> None:
    """No relation between two keyframes: no scatter estimate (the report says why), and the
    plain relations NEES stands."""
    from slam.evaluation.report import evaluate_results

    traj, truth, _, path = _synthetic_run(4, tmp_path, 30)
    rel = _relations(truth, traj.timestamps, _pairs(30)["one keyframe, two scans"])
    cov = RunCovariances.from_file(path)
    report = evaluate_results(
        traj,
        relations=rel,
        relative_covariances=cov.relative_covariances,
        odometry=traj,
        keyframe_timestamps=cov.graph_file.timestamps,
    )
    out = report.to_dict()
    assert "too few" in out["relations_noise"]["skipped"]
    assert out["relations_nees"]["n"] == len(rel)
    assert "relations_nees_with_relations_noise" not in out
    assert "not estimated" in report.format_table()


@pytest.mark.parametrize(
    ("lower_mean", "upper_mean", "verdict"),
    [(1.7, 2.9, "consistent"), (2.0, 7.8, "consistent"), (3.6, 9.0, "over-confident"),
     (1.2, 2.5, "under-confident")],
)  # fmt: skip
def test_the_two_relations_nees_bracket_the_runs(lower_mean, upper_mean, verdict):
    """The plain NEES (the relations' scatter counted as the run's error) and the one with the
    hat's scatter (up to the run's own variance counted as the relations') bracket the run's:
    it is shown over- or under-confident only when the whole bracket lies beyond the interval."""
    from slam.evaluation.relations_nees import RelationsNees
    from slam.evaluation.report import EvaluationReport

    def nees(mean: float) -> RelationsNees:
        return RelationsNees(100, mean, mean, 2.8, 3.2, 0.9, mean, 0.0, 7.81)

    report = EvaluationReport(
        n_poses=10,
        frame="laser",
        relations_nees=nees(upper_mean),
        relations_nees_with_relations_noise=nees(lower_mean),
    )
    bracket = report.to_dict()["relations_nees_bracket"]
    assert bracket == {"lower": lower_mean, "upper": upper_mean, "verdict": verdict}
    assert f"[{lower_mean:.3f}, {upper_mean:.3f}]" in report.format_table()
    plain = EvaluationReport(n_poses=10, frame="laser", relations_nees=nees(upper_mean))
    assert "relations_nees_bracket" not in plain.to_dict()
