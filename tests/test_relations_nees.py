"""Relations NEES: relative-pose covariances recomputed from graph.g2o (slam.graph.relative)."""

from __future__ import annotations

import json
import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from slam.evaluation.relations_nees import relation_error_vectors, relations_nees
from slam.geometry import adjoint_pose2, pose_between, pose_compose, pose_exp, pose_inverse
from slam.graph.batch import BatchSolver
from slam.graph.config import SolverConfig
from slam.graph.linear import keys_of
from slam.graph.relative import RunCovariances
from slam.graph.synthetic import synthetic_problem
from slam.io.g2o import read_line_graph_g2o, write_line_graph_g2o
from slam.io.relations import Relations
from slam.io.trajectory import Trajectory
from slam.models.motion import MotionNoiseConfig

MOTION = MotionNoiseConfig(
    sigma_xy_min_m=1e-5,
    sigma_xy_per_m=0.03,
    sigma_xy_per_rad=0.0,
    sigma_theta_min_rad=1e-6,
    sigma_theta_per_m=0.02,
    sigma_theta_per_rad=0.03,
)
OFFSETS = np.array([[0.1, 0.005, 0.04], [0.2, 0.01, 0.09]])  # true offsets of two scans


def _noisy_step(rng: np.random.Generator, u: np.ndarray) -> np.ndarray:
    """``u ∘ Exp(w)``, ``w ~ N(0, Q(u))`` (the motion model's odometry)."""
    w = np.linalg.cholesky(MOTION.covariance(u)) @ rng.standard_normal(3)
    return np.asarray(pose_compose(u, pose_exp(w)))


def _synthetic_run(
    seed: int,
    tmp_path: Path,
    n_kf: int = 30,
    offset_covs: np.ndarray | None = None,
    name: str = "",
) -> tuple[Trajectory, np.ndarray, np.ndarray, Path]:
    """A solved synthetic graph written as graph.g2o, with two non-keyframe scans per keyframe.

    Returns the run's trajectory (all scans), the true scan poses, and the scans' keyframes.
    The scans' odometry is a random walk from their keyframe (the model of the covariances);
    ``offset_covs`` ``(3 n_kf, 3, 3)`` is written as the scans' match covariances.
    """
    rng = np.random.default_rng(seed)
    prob = synthetic_problem(n_kf, seed=seed, motion=MOTION)
    BatchSolver(SolverConfig(robust_kernel="none")).solve(prob.graph)
    est_kf = prob.graph.poses.copy()
    poses, truth, kf_of, offsets, is_kf = [], [], [], [], []
    for k in range(n_kf):
        poses.append(est_kf[k])
        truth.append(prob.poses_true[k])
        kf_of.append(k)
        offsets.append(np.zeros(3))
        is_kf.append(True)
        d1 = _noisy_step(rng, OFFSETS[0])
        d2 = pose_compose(d1, _noisy_step(rng, pose_between(OFFSETS[0], OFFSETS[1])))
        for u, d in zip(OFFSETS, (d1, d2), strict=True):
            poses.append(pose_compose(est_kf[k], d))
            truth.append(pose_compose(prob.poses_true[k], u))
            kf_of.append(k)
            offsets.append(np.asarray(d))
            is_kf.append(False)
    n = len(poses)
    stamps = 1000.0 + 0.125 * np.arange(n)
    result = SimpleNamespace(
        timestamps=stamps,
        is_keyframe=np.array(is_kf),
        keyframe_of_scan=np.array(kf_of),
    )
    path = tmp_path / f"graph{seed}{name}.g2o"
    write_line_graph_g2o(
        path,
        prob.graph,
        result,
        scan_offsets=np.array(offsets),
        motion_noise=MOTION,
        robust_kernel=("none", 1.0),
        scan_offset_covariances=offset_covs,
    )
    traj = Trajectory(np.asarray(stamps, dtype=np.float64), np.array(poses))
    return traj, np.array(truth), np.array(kf_of), path


def _relations(truth: np.ndarray, stamps: np.ndarray, pairs: np.ndarray) -> Relations:
    rel = pose_between(truth[pairs[:, 0]], truth[pairs[:, 1]])
    m = pairs.shape[0]
    return Relations(
        stamps[pairs[:, 0]],
        stamps[pairs[:, 1]],
        rel,
        np.zeros(m),
        np.zeros(m),
        np.zeros(m),
        np.arange(m, dtype=np.int64),
    )


def _pairs(n_kf: int) -> dict[str, np.ndarray]:
    """Scan pairs by kind (scan 3k is keyframe k, 3k+1 and 3k+2 hang from it)."""
    k = np.arange(n_kf - 6)
    return {
        "keyframes": np.column_stack([3 * k, 3 * k + 3]),
        "keyframe to its scan": np.column_stack([3 * k, 3 * k + 2]),
        "one keyframe, two scans": np.column_stack([3 * k + 1, 3 * k + 2]),
        "backwards, one keyframe": np.column_stack([3 * k + 2, 3 * k + 1]),
        "scans of two keyframes": np.column_stack([3 * k + 2, 3 * k + 7]),
        "long, backwards": np.column_stack([3 * k + 16, 3 * k + 1]),
    }


def test_g2o_states_how_every_scan_hangs_from_the_graph(tmp_path):
    traj, _, kf_of, path = _synthetic_run(0, tmp_path, n_kf=8)
    back = read_line_graph_g2o(path)
    assert back.robust_kernel == ("none", 1.0)
    assert back.motion_noise is not None
    assert MotionNoiseConfig(**back.motion_noise) == MOTION
    assert back.prior_pose is not None and back.prior_information is not None
    not_kf = np.arange(traj.timestamps.shape[0]) % 3 != 0
    assert back.offset_keyframes is not None
    np.testing.assert_array_equal(back.offset_keyframes, kf_of[not_kf])
    assert back.offset_timestamps is not None
    np.testing.assert_allclose(back.offset_timestamps, traj.timestamps[not_kf])
    assert back.timestamps is not None
    np.testing.assert_allclose(back.timestamps, traj.timestamps[::3])


def test_keyframe_marginals_round_trip_through_the_file(tmp_path):
    """The graph rebuilt from graph.g2o gives the solver's own marginals."""
    prob = synthetic_problem(25, seed=4, motion=MOTION)
    solver = BatchSolver(SolverConfig(robust_kernel="cauchy", robust_k=3.0))
    solver.solve(prob.graph)
    marg = solver.marginals(prob.graph)
    stamps = 10.0 + np.arange(25) * 0.5
    result = SimpleNamespace(
        timestamps=stamps, is_keyframe=np.ones(25, bool), keyframe_of_scan=np.arange(25)
    )
    path = tmp_path / "g.g2o"
    write_line_graph_g2o(
        path,
        prob.graph,
        result,
        scan_offsets=np.zeros((25, 3)),
        motion_noise=MOTION,
        robust_kernel=("cauchy", 3.0),
    )
    cov = RunCovariances.from_file(path)
    mine = cov.keyframe_covariances(np.arange(25))
    ref = np.array([marg.marginalCovariance(k) for k in keys_of("x", np.arange(25))])
    np.testing.assert_allclose(mine, ref, rtol=1e-5, atol=1e-14)


def test_relations_nees_is_chi2_3_with_exact_models(tmp_path):
    """Monte Carlo on solved synthetic graphs with non-keyframe scans on a random walk: the
    NEES of every kind of relation (keyframes, scans of one keyframe, of two, backwards) is
    about 3, and the per-pose-marginal shortcut would not be."""
    n_kf = 30
    by_kind: dict[str, list[np.ndarray]] = {k: [] for k in _pairs(n_kf)}
    naive = []
    for seed in range(12):
        traj, truth, _, path = _synthetic_run(seed, tmp_path, n_kf)
        cov = RunCovariances.from_file(path)
        for kind, pairs in _pairs(n_kf).items():
            rel = _relations(truth, traj.timestamps, pairs)
            res = relations_nees(traj, rel, cov.relative_covariances)
            by_kind[kind].append(res.values)
        # the shortcut: relative covariance from the per-pose marginals, no correlation
        pairs = _pairs(n_kf)["keyframes"]
        rel = _relations(truth, traj.timestamps, pairs)
        P = cov.keyframe_covariances(pairs[:, 0] // 3), cov.keyframe_covariances(pairs[:, 1] // 3)
        rho = pose_between(traj.poses[pairs[:, 0]], traj.poses[pairs[:, 1]])
        F = adjoint_pose2(pose_inverse(rho))
        C = F @ P[0] @ np.swapaxes(F, 1, 2) + P[1]
        e = relation_error_vectors(traj.poses[pairs[:, 0]], traj.poses[pairs[:, 1]], rel)
        naive.append(np.einsum("mi,mij,mj->m", e, np.linalg.inv(C), e))
    for kind, values in by_kind.items():
        v = np.concatenate(values)
        assert 2.4 < v.mean() < 3.6, (kind, v.mean())
    allv = np.concatenate([np.concatenate(v) for v in by_kind.values()])
    assert 2.7 < allv.mean() < 3.3
    assert np.mean(allv <= 7.8147) == pytest.approx(0.95, abs=0.03)
    assert np.concatenate(naive).mean() < 1.5  # without the correlation: far too large


def test_reported_base_frame_moves_the_covariance_with_the_mounting(tmp_path):
    """A base-frame trajectory (pose ∘ M⁻¹) and the relations moved to the base give the
    same NEES as the laser frame."""
    traj, truth, _, path = _synthetic_run(7, tmp_path, n_kf=20)
    pairs = np.concatenate(list(_pairs(20).values()))
    mount = np.array([0.2, -0.05, 0.1])
    minv = np.broadcast_to(pose_inverse(mount), traj.poses.shape)
    base_traj = Trajectory(traj.timestamps, pose_compose(traj.poses, minv))
    base_truth = pose_compose(truth, minv)
    laser = relations_nees(
        traj,
        _relations(truth, traj.timestamps, pairs),
        RunCovariances.from_file(path).relative_covariances,
    )
    base = relations_nees(
        base_traj,
        _relations(base_truth, traj.timestamps, pairs),
        RunCovariances.from_file(path, pose_base_laser=mount).relative_covariances,
    )
    np.testing.assert_allclose(base.values, laser.values, rtol=1e-6)


def _cli(argv: list[str]) -> int:
    from slam.cli import main

    try:
        main(argv)
    except SystemExit as exc:
        return int(exc.code or 0)
    return 0


def test_lineslam_evaluate_reports_the_relations_nees(tmp_path, capsys):
    """simulate → slam (batch, exact line model) → evaluate --relations: metrics.json holds
    relations_nees; the relative covariance from the first scan (pinned by the prior) to any
    scan, keyframe or not, is that scan's covariance in trajectory_covariance.txt."""
    from slam.io.results import read_results

    sim, out = tmp_path / "sim", tmp_path / "run"
    config = tmp_path / "exact.toml"
    config.write_text("[slam]\nline_model_sigma_r_m = 0.0\nline_model_sigma_alpha_rad = 0.0\n")
    assert _cli(["simulate", "loop", "--out", str(sim), "--spacing", "0.1", "--seed", "5",
                 "--quiet", "--no-beam-hits"]) == 0  # fmt: skip
    assert _cli(["slam", str(sim / "log.clf"), "--out", str(out), "--config", str(config),
                 "--backend", "batch", "--max-scans", "120", "--quiet"]) == 0  # fmt: skip
    assert _cli(["evaluate", str(out), "--relations", str(sim / "relations.txt"), "--quiet"]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    nees = metrics["relations_nees"]
    assert nees["n"] == metrics["relations"]["n_used"] > 50
    assert set(nees) >= {"mean", "bounds_95", "fraction_inside_95", "n", "median"}
    assert 0.0 < nees["mean"] < 20.0 and 0.0 <= nees["fraction_inside_95"] <= 1.0
    assert sum(g["n"] for g in nees["by_gap"]) == nees["n"]
    # the simulator's relations are exact: the three-cornered hat's bound on their scatter is
    # of the order of the run's own error (millimetres), not of a wrong frame (decimetres)
    noise = metrics["relations_noise"]
    assert noise["n"] >= 10 and noise["keyframes_only"]
    assert metrics["odometry_log"] == str(sim / "log.clf")
    assert np.all(np.abs(noise["rms_relations_xy_theta"][:2]) < 0.01)
    assert abs(noise["rms_relations_xy_theta"][2]) < 0.005
    assert "relations_nees_with_relations_noise" in metrics
    results = read_results(out)
    cov = RunCovariances.from_results(out, results.summary)
    t = results.trajectory.timestamps
    assert results.covariances is not None
    offsets = read_line_graph_g2o(out / "graph.g2o").offset_timestamps
    assert offsets is not None and 0 < offsets.size < t.size  # scans that are not keyframes
    import gtsam

    graph, values = gtsam.readG2o(str(out / "graph.g2o"), False)  # the extension is skipped
    text = (out / "graph.g2o").read_text()
    assert values.size() == t.size - offsets.size == text.count("VERTEX_SE2 ")
    assert graph.size() == text.count("\nEDGE_SE2 ")  # every odometry edge, nothing else
    rel = cov.relative_covariances(np.full(t.size, t[0]), t)
    np.testing.assert_allclose(rel[1:], results.covariances[1:], rtol=0.02, atol=1e-7)
    assert _cli(["evaluate", str(out), "--relations", str(sim / "relations.txt"),
                 "--no-relations-nees", "--quiet"]) == 0  # fmt: skip
    assert "relations_nees" not in json.loads((out / "metrics.json").read_text())
    # a graph.g2o of an older lineslam (none of the lines for the covariances): a warning,
    # the rest evaluated
    newer = ("LINESLAM_SCAN_OFFSET", "LINESLAM_MOTION_NOISE", "LINESLAM_ROBUST_KERNEL",
             "LINESLAM_PRIOR_SE2")  # fmt: skip
    lines = (out / "graph.g2o").read_text().splitlines(keepends=True)
    (out / "graph.g2o").write_text("".join(x for x in lines if not x.startswith(newer)))
    assert _cli(["evaluate", str(out), "--relations", str(sim / "relations.txt")]) == 0
    assert "no relations NEES" in capsys.readouterr().err
    assert "relations_nees" not in json.loads((out / "metrics.json").read_text())


@pytest.mark.parametrize("mount", [None, (0.2, -0.05, 0.1)])
def test_joint_scan_covariance_holds_every_relative_covariance(tmp_path, mount):
    """The joint covariance of all scans (keyframes and the scans hanging from them) gives,
    for every kind of pair, the relative covariance RunCovariances computes pair by pair, and
    its diagonal blocks are each scan's own covariance."""
    traj, _, _, path = _synthetic_run(3, tmp_path, n_kf=12)
    cov = RunCovariances.from_file(path, pose_base_laser=mount)
    poses = traj.poses
    if mount is not None:
        poses = pose_compose(poses, np.broadcast_to(pose_inverse(np.array(mount)), poses.shape))
    S = cov.joint_scan_covariance(traj.timestamps)
    n = traj.timestamps.shape[0]
    assert S.shape == (3 * n, 3 * n)
    np.testing.assert_allclose(S, S.T, atol=0.0)
    for pairs in _pairs(12).values():
        t1, t2 = traj.timestamps[pairs[:, 0]], traj.timestamps[pairs[:, 1]]
        expected = cov.relative_covariances(t1, t2)
        for (a, b), want in zip(pairs.tolist(), expected, strict=True):
            rho = pose_between(poses[a], poses[b])
            A = np.zeros((3, 3 * n))
            A[:, 3 * a : 3 * a + 3] = -adjoint_pose2(pose_inverse(rho))
            A[:, 3 * b : 3 * b + 3] += np.eye(3)
            np.testing.assert_allclose(A @ S @ A.T, want, rtol=1e-6, atol=1e-14)
    # a keyframe's block is its marginal; a scan on it adds its odometry noise
    kf_blocks = cov.keyframe_covariances(np.arange(12))
    F = np.eye(3) if mount is None else adjoint_pose2(np.array(mount))
    np.testing.assert_allclose(S[:3, :3], F @ kf_blocks[0] @ F.T, rtol=1e-9, atol=1e-16)
    assert np.trace(S[3:6, 3:6]) > np.trace(S[:3, :3])


def test_relation_error_draws_have_the_runs_joint_covariance(tmp_path):
    """Joint draws of the relations' errors (keyframes from the information matrix, the other
    scans by their odometry) have, relation by relation and between relations sharing scans,
    the covariance the joint scan covariance gives; the draws repeat for a seed."""
    traj, _, _, path = _synthetic_run(5, tmp_path, n_kf=10)
    mount = np.array([0.2, -0.05, 0.1])
    cov = RunCovariances.from_file(path, pose_base_laser=mount)
    pairs = np.concatenate([p[:4] for p in _pairs(10).values()])
    t1, t2 = traj.timestamps[pairs[:, 0]], traj.timestamps[pairs[:, 1]]
    eta = np.concatenate(list(cov.relation_error_draws(t1, t2, 6000, seed=3, chunk=700)))
    assert eta.shape == (6000, pairs.shape[0], 3)
    again = next(iter(cov.relation_error_draws(t1, t2, 700, seed=3, chunk=700)))
    np.testing.assert_array_equal(again, eta[:700])
    # the analytic joint covariance of the stacked relation errors, in the reported frame
    S = cov.joint_scan_covariance(traj.timestamps)
    poses = pose_compose(traj.poses, np.broadcast_to(pose_inverse(mount), traj.poses.shape))
    n, m = traj.timestamps.shape[0], pairs.shape[0]
    J = np.zeros((3 * m, 3 * n))
    for r, (a, b) in enumerate(pairs.tolist()):
        J[3 * r : 3 * r + 3, 3 * a : 3 * a + 3] -= adjoint_pose2(
            pose_inverse(pose_between(poses[a], poses[b]))
        )
        J[3 * r : 3 * r + 3, 3 * b : 3 * b + 3] += np.eye(3)
    want = J @ S @ J.T
    flat = eta.reshape(eta.shape[0], -1)
    got = flat.T @ flat / flat.shape[0]
    scale = np.sqrt(np.outer(np.diag(want), np.diag(want)))
    assert np.max(np.abs(got - want) / scale) < 0.07  # correlations to 1/sqrt(6000) ≈ 0.013
    np.testing.assert_allclose(
        np.diag(want).reshape(m, 3),
        np.einsum("mii->mi", cov.relative_covariances(t1, t2)),
        rtol=1e-6,
    )


# --- scans matched against their keyframe: the offset's covariance Σ_s in graph.g2o ---


def _match_covariances(n_kf: int, seed: int = 11) -> np.ndarray:
    """Σ_s for the scans of :func:`_synthetic_run` (scan 3k is keyframe k): on keyframe k,
    k % 4 == 0 both scans matched, 1 the first, 2 the second, 3 neither (NaN rows)."""
    rng = np.random.default_rng(seed)
    covs = np.full((3 * n_kf, 3, 3), np.nan)
    for k in range(n_kf):
        for j in {0: (1, 2), 1: (1,), 2: (2,), 3: ()}[k % 4]:
            L = rng.standard_normal((3, 3)) * np.array([[0.004], [0.003], [0.002]])
            covs[3 * k + j] = L @ L.T + np.diag([1e-7, 1e-7, 1e-8])
    return covs


def _matched_run(
    tmp_path: Path, seed: int = 3, n_kf: int = 12
) -> tuple[Trajectory, np.ndarray, np.ndarray, Path, np.ndarray]:
    covs = _match_covariances(n_kf)
    traj, truth, kf_of, path = _synthetic_run(seed, tmp_path, n_kf, covs, name="_matched")
    return traj, truth, kf_of, path, covs


def _offset_lines(path: Path) -> list[str]:
    return [x for x in path.read_text().splitlines() if x.startswith("LINESLAM_SCAN_OFFSET ")]


def test_g2o_round_trip_of_scan_offset_covariances(tmp_path):
    """Without match covariances (None or NaN rows) the file is byte for byte the odometry
    one; with them a matched scan's line has the six covariance fields, read back."""
    _, _, _, plain = _synthetic_run(3, tmp_path, n_kf=12)
    nan_rows = np.full((36, 3, 3), np.nan)
    nan_rows[::3] = np.eye(3)  # keyframes' rows are not read
    _, _, _, nan_path = _synthetic_run(3, tmp_path, 12, nan_rows, name="_nan")
    assert nan_path.read_bytes() == plain.read_bytes()
    lines = _offset_lines(plain)
    assert len(lines) == 24
    six = r"LINESLAM_SCAN_OFFSET \d+ \d+\.\d{6}( -?\d+\.\d{9}){3}"
    assert all(re.fullmatch(six, x) for x in lines)
    back = read_line_graph_g2o(plain)
    assert back.offset_covariances is not None and back.offset_covariances.shape == (24, 3, 3)
    assert np.isnan(back.offset_covariances).all()

    _, _, _, path, covs = _matched_run(tmp_path)
    matched_lines = _offset_lines(path)
    not_kf = np.arange(36) % 3 != 0
    matched = np.isfinite(covs[not_kf]).all(axis=(1, 2))
    assert 0 < matched.sum() < 24
    for was, line, m in zip(lines, matched_lines, matched, strict=True):
        assert line.split() == (was.split() + line.split()[6:]) and len(line.split()) == (
            12 if m else 6
        )
    assert re.fullmatch(six + r"( -?\d\.\d{9}e[-+]\d+){6}", matched_lines[0])
    got = read_line_graph_g2o(path)
    ref = read_line_graph_g2o(plain)
    assert got.offsets is not None and ref.offsets is not None
    np.testing.assert_array_equal(got.offsets, ref.offsets)
    assert got.offset_covariances is not None
    np.testing.assert_allclose(got.offset_covariances[matched], covs[not_kf][matched], rtol=1e-9)
    assert np.isnan(got.offset_covariances[~matched]).all()
    # the pose graph is still g2o's and GTSAM's
    import gtsam

    graph, values = gtsam.readG2o(str(path), False)
    assert values.size() == 12 and graph.size() == 11


def test_scan_offset_covariances_are_checked(tmp_path):
    """The writer refuses a wrong shape or a covariance that is not symmetric positive
    definite; the reader names the file and line of a malformed LINESLAM_SCAN_OFFSET."""
    from slam.errors import InputError, LogFormatError

    covs = _match_covariances(12)
    with pytest.raises(InputError, match="scan_offset_covariances"):
        _synthetic_run(3, tmp_path, 12, covs[:-1], name="_short")
    for bad in (
        np.diag([1e-4, 1e-4, -1e-6]),
        np.array([[1e-4, 2e-5, 0], [0, 1e-4, 0], [0, 0, 1e-5]]),
    ):
        wrong = covs.copy()
        wrong[4] = bad
        with pytest.raises(InputError, match="row 4"):
            _synthetic_run(3, tmp_path, 12, wrong, name="_bad")
    partly = covs.copy()
    partly[5, 0, 0] = 1e-4  # an odometry row (NaN) with one number
    with pytest.raises(InputError, match="row 5"):
        _synthetic_run(3, tmp_path, 12, partly, name="_bad")

    _, _, _, path, _ = _matched_run(tmp_path)
    text = path.read_text().splitlines(keepends=True)
    at = next(
        i
        for i, x in enumerate(text)
        if x.startswith("LINESLAM_SCAN_OFFSET ") and len(x.split()) == 12
    )
    fields = text[at].split()
    for edit in (
        fields[:9],  # a covariance cut short
        [*fields[:11], "x"],  # not a number
        [*fields[:6], "1e-4", "0", "0", "1e-4", "0", "-1e-6"],  # not positive definite
        [*fields[:6], "1e-4", "0", "0", "1e-4", "0", "nan"],
    ):
        broken = tmp_path / "broken.g2o"
        broken.write_text("".join([*text[:at], " ".join(edit) + "\n", *text[at + 1 :]]))
        with pytest.raises(
            LogFormatError, match=re.escape(f"{broken}:{at + 1}: LINESLAM_SCAN_OFFSET")
        ):
            read_line_graph_g2o(broken)


def test_two_matched_scans_on_one_keyframe_are_independent(tmp_path):
    """On one keyframe, a matched scan's noise is its Σ_s, independent of the other scan's:
    Cov(ρ) = F Σ_a Fᵀ + Σ_b (F = Ad(ρ⁻¹)), moved to ρ⁻¹ backwards; two odometry scans keep
    the odometry between them, Q(δ_a⁻¹ δ_b)."""
    traj, _, _, path, covs = _matched_run(tmp_path)
    cov = RunCovariances.from_file(path)
    t = traj.timestamps
    offsets = pose_between(traj.poses[(np.arange(36) // 3) * 3], traj.poses)
    checked = set()
    for k in range(12):
        a, b = 3 * k + 1, 3 * k + 2
        da, db = offsets[a], offsets[b]
        rho = pose_between(da, db)
        F = adjoint_pose2(pose_inverse(rho))
        Sa = covs[a] if np.isfinite(covs[a]).all() else MOTION.covariance(da)
        Sb = covs[b] if np.isfinite(covs[b]).all() else MOTION.covariance(db)
        want = F @ Sa @ F.T + Sb if k % 4 != 3 else MOTION.covariance(rho)
        got = cov.relative_covariances(t[[a, b, 3 * k, 3 * k]], t[[b, a, a, b]])
        np.testing.assert_allclose(got[0], want, rtol=1e-6, atol=1e-15)
        G = adjoint_pose2(rho)
        np.testing.assert_allclose(got[1], G @ want @ G.T, rtol=1e-6, atol=1e-15)
        # from the keyframe: the scan's own noise
        np.testing.assert_allclose(got[2], Sa, rtol=1e-6, atol=1e-15)
        np.testing.assert_allclose(got[3], Sb, rtol=1e-6, atol=1e-15)
        if k % 4 != 3:  # not the odometry's between them
            assert not np.allclose(got[0], MOTION.covariance(rho), rtol=0.05)
        checked.add(k % 4)
    assert checked == {0, 1, 2, 3}


def test_matched_scan_on_another_keyframe_uses_its_own_covariance(tmp_path):
    """Between keyframes, a matched scan's Σ_s takes the place of Q(δ_s): the relative
    covariance moves by exactly Ad(ρ⁻¹)(Σ_a − Q(δ_a))Ad(ρ⁻¹)ᵀ, or Σ_b − Q(δ_b)."""
    traj, _, _, path, covs = _matched_run(tmp_path)
    _, _, _, plain = _synthetic_run(3, tmp_path, n_kf=12)
    matched, odometry = RunCovariances.from_file(path), RunCovariances.from_file(plain)
    t, poses = traj.timestamps, traj.poses
    kf_pose = poses[(np.arange(36) // 3) * 3]
    for a, b in ((1, 8), (8, 1), (4, 14), (2, 35), (11, 3)):
        rho = pose_between(poses[a], poses[b])
        F = adjoint_pose2(pose_inverse(rho))
        want = np.zeros((3, 3))
        if np.isfinite(covs[a]).all():
            want += F @ (covs[a] - MOTION.covariance(pose_between(kf_pose[a], poses[a]))) @ F.T
        if np.isfinite(covs[b]).all():
            want += covs[b] - MOTION.covariance(pose_between(kf_pose[b], poses[b]))
        diff = matched.relative_covariances(t[[a]], t[[b]]) - odometry.relative_covariances(
            t[[a]], t[[b]]
        )
        assert np.abs(want).max() > 1e-6 or (a, b) == (11, 3)  # the last: no matched scan
        np.testing.assert_allclose(diff[0], want, rtol=1e-6, atol=1e-12)


@pytest.mark.parametrize("mount", [None, (0.2, -0.05, 0.1)])
def test_joint_scan_covariance_holds_relative_covariances_of_matched_scans(tmp_path, mount):
    """With matched scans, the joint covariance of all scans gives every pair's relative
    covariance as RunCovariances computes it pair by pair, its diagonal blocks each scan's
    own covariance, and a matched scan no cross-covariance of noise with its neighbour."""
    traj, _, _, path, covs = _matched_run(tmp_path)
    cov = RunCovariances.from_file(path, pose_base_laser=mount)
    poses = traj.poses
    if mount is not None:
        poses = pose_compose(poses, np.broadcast_to(pose_inverse(np.array(mount)), poses.shape))
    S = cov.joint_scan_covariance(traj.timestamps)
    n = traj.timestamps.shape[0]
    pairs = np.concatenate(list(_pairs(12).values()))
    expected = cov.relative_covariances(traj.timestamps[pairs[:, 0]], traj.timestamps[pairs[:, 1]])
    for (a, b), want in zip(pairs.tolist(), expected, strict=True):
        rho = pose_between(poses[a], poses[b])
        A = np.zeros((3, 3 * n))
        A[:, 3 * a : 3 * a + 3] = -adjoint_pose2(pose_inverse(rho))
        A[:, 3 * b : 3 * b + 3] += np.eye(3)
        np.testing.assert_allclose(A @ S @ A.T, want, rtol=1e-6, atol=1e-14)
    # keyframe 0: both scans matched; keyframe 3: neither (the shared odometry)
    noise = cov.odometry_noise(cov.scans_of(traj.timestamps[[1, 2]]))
    np.testing.assert_allclose(noise[:3, :3], covs[1])
    np.testing.assert_allclose(noise[3:, 3:], covs[2])
    np.testing.assert_array_equal(noise[:3, 3:], 0.0)
    assert np.abs(cov.odometry_noise(cov.scans_of(traj.timestamps[[10, 11]]))[:3, 3:]).max() > 0
    # a matched scan's block is its keyframe's moved along the offset plus Σ_s
    F = np.eye(3) if mount is None else adjoint_pose2(np.array(mount))
    kf0 = cov.keyframe_covariances(np.array([0]))[0]
    G = adjoint_pose2(pose_inverse(pose_between(traj.poses[0], traj.poses[1])))
    np.testing.assert_allclose(
        S[3:6, 3:6], F @ (G @ kf0 @ G.T + covs[1]) @ F.T, rtol=1e-9, atol=1e-16
    )


def test_relation_error_draws_of_matched_scans(tmp_path):
    """The joint draws use the matched scans' Σ_s: relation by relation their covariance is
    the relative covariance."""
    traj, _, _, path, _ = _matched_run(tmp_path, seed=5, n_kf=12)
    cov = RunCovariances.from_file(path)
    pairs = np.concatenate([p[:4] for p in _pairs(12).values()])
    t1, t2 = traj.timestamps[pairs[:, 0]], traj.timestamps[pairs[:, 1]]
    eta = np.concatenate(list(cov.relation_error_draws(t1, t2, 6000, seed=3, chunk=1000)))
    want = cov.relative_covariances(t1, t2)
    got = np.einsum("kmi,kmj->mij", eta, eta) / eta.shape[0]
    sd = np.sqrt(np.einsum("mii->mi", want))
    corr = (got - want) / (sd[:, :, None] * sd[:, None, :])
    assert np.abs(corr).max() < 0.07


def test_lineslam_evaluate_writes_every_relation_with_per_relation(tmp_path, capsys):
    """``--per-relation`` writes relation_errors.csv: one row per relation used, in the
    relations file's order, whose errors and NEES average to metrics.json's; the relations
    NEES columns are NaN with ``--no-relations-nees``; without ``--relations`` it is an
    error, not a silent no-op."""
    from slam.io.relations import read_relations

    sim, out = tmp_path / "sim", tmp_path / "run"
    assert _cli(["simulate", "loop", "--out", str(sim), "--spacing", "0.1", "--seed", "5",
                 "--quiet", "--no-beam-hits"]) == 0  # fmt: skip
    assert _cli(["slam", str(sim / "log.clf"), "--out", str(out), "--backend", "batch",
                 "--max-scans", "120", "--quiet"]) == 0  # fmt: skip
    relations = sim / "relations.txt"
    assert _cli(["evaluate", str(out), "--relations", str(relations), "--per-relation"]) == 0
    assert "relation_errors.csv" in capsys.readouterr().out
    metrics = json.loads((out / "metrics.json").read_text())
    rows = np.genfromtxt(out / "relation_errors.csv", delimiter=",", names=True)
    assert rows.dtype.names == ("t1_s", "t2_s", "trans_error_m", "rot_error_deg", "nees",
                                "nees_with_relations_noise")  # fmt: skip
    assert rows.size == metrics["relations"]["n_used"] == metrics["relations_nees"]["n"] > 50
    inside = read_relations(relations)
    inside = np.isin(inside.t1, rows["t1_s"]) & np.isin(inside.t2, rows["t2_s"])
    np.testing.assert_allclose(rows["t1_s"], read_relations(relations).t1[inside], atol=1e-6)
    for column, key in (("trans_error_m", "abs_trans_m"), ("rot_error_deg", "abs_rot_deg")):
        assert rows[column].mean() == pytest.approx(metrics["relations"][key]["mean"], rel=1e-6)
    assert rows["nees"].mean() == pytest.approx(metrics["relations_nees"]["mean"], rel=1e-6)
    with_noise = metrics["relations_nees_with_relations_noise"]["mean"]
    assert rows["nees_with_relations_noise"].mean() == pytest.approx(with_noise, rel=1e-6)
    assert _cli(["evaluate", str(out), "--relations", str(relations), "--per-relation",
                 "--no-relations-nees", "--quiet"]) == 0  # fmt: skip
    rows = np.genfromtxt(out / "relation_errors.csv", delimiter=",", names=True)
    assert np.all(np.isnan(rows["nees"])) and np.all(np.isfinite(rows["trans_error_m"]))
    gt = sim / "ground_truth.tum"
    assert _cli(["evaluate", str(out), "--ground-truth", str(gt), "--per-relation"]) == 2
    assert "--per-relation needs --relations" in capsys.readouterr().err
