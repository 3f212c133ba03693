"""LineSlam on simulated line worlds: loop closing, map, consistency, degradation, result files."""

from __future__ import annotations

import json
import warnings
from dataclasses import replace

import numpy as np
import pytest
from line_world import (
    corridor_loop,
    loop_path,
    relations_error,
    simulate_run,
    straight_corridor,
)

from linefit.line import Line
from slam.config import RunConfig
from slam.errors import ConfigError, InputError
from slam.frontend.config import LoopClosureConfig
from slam.geometry import pose_between, pose_log
from slam.graph import SolverConfig
from slam.line_slam import FusionConfig, KeyframeConfig, LineSlam, SlamConfig, SlamWarning
from slam.line_slam.report import WARN_LOST, WARN_NO_LINES, WARN_PARALLEL
from slam.models import MotionNoiseConfig
from slam.result import SlamResult
from slam.types import Scan

MOTION = MotionNoiseConfig(sigma_xy_per_m=0.03, sigma_theta_per_m=0.03, sigma_theta_per_rad=0.03)
EXACT_LINES = {"line_model_sigma_r_m": 0.0, "line_model_sigma_alpha_rad": 0.0}
"""The line world's measurements have exactly the covariances they carry (no model error): the
estimator is given the true noise model, lines and motion."""


def run_slam(run, config: SlamConfig, lines=None):
    slam = LineSlam(config)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SlamWarning)
        reports = [
            slam.add_scan(s, ls)
            for s, ls in zip(run.scans, run.lines if lines is None else lines, strict=True)
        ]
        slam.optimize()
    return slam, slam.result(), reports


@pytest.fixture(scope="module")
def loop_runs():
    """A 16 m × 8 m corridor loop (walls cut by doors) driven 1¼ times, metres of drift."""
    world = corridor_loop(piece=3.0, door=1.0)
    path = loop_path(16, 8, 0.4, laps=1.25)
    run = simulate_run(world, path, seed=1, motion=MOTION)
    out = {}
    for backend in ("isam2", "batch"):
        solver = SolverConfig(batch_interval=5)  # periodic batch solves keep the test short
        out[backend] = run_slam(
            run, SlamConfig(backend=backend, motion=MOTION, **EXACT_LINES, solver=solver)
        )
    return world, path, run, out


def test_loop_closing_beats_odometry_by_far(loop_runs):
    _, path, run, out = loop_runs
    slam, res, _ = out["isam2"]
    odo_err = np.hypot(*(run.odometry[:, :2] - path[:, :2]).T)
    assert odo_err.max() > 3.0  # metres of drift
    err = pose_log(pose_between(path, res.poses_world_laser))
    ate = np.sqrt(np.mean(np.sum(err[:, :2] ** 2, axis=1)))
    assert ate < 0.08 and ate < 0.03 * np.sqrt(np.mean(odo_err**2))
    for gap in (5, 40, 120):  # 2 m, 16 m, 48 m apart along the path
        rel = relations_error(res.poses_world_laser, path, gap).mean()
        rel_odo = relations_error(run.odometry, path, gap).mean()
        assert rel < 0.05 and rel_odo > 0.05 and rel < 0.2 * rel_odo
    # the start was re-observed at the end: landmarks of the first poses have late factors
    g = slam.graph
    early = np.unique(g.factor_landmark[g.factor_pose < 5])
    late_poses = g.factor_pose[np.isin(g.factor_landmark, early)]
    assert late_poses.max() > 0.8 * g.n_poses


def test_accepted_closures_agree_with_the_front_end_trajectory(loop_runs):
    """With the true noise models, every accepted closure is a plausible draw against the front
    end's own trajectory and drift (squared Mahalanobis distance below χ²(3)'s 99.9 % point);
    with ``confirmations = 1`` no hypothesis is judged before a consistent second one."""
    _, _, run, out = loop_runs
    for backend in ("isam2", "batch"):
        slam = out[backend][0]
        accepted = [e for e in slam.loop_closer.attempts if e.accepted]
        assert accepted
        assert all(0.0 <= e.correction_chi2 < 16.27 for e in accepted)
    config = SlamConfig(
        motion=MOTION,
        **EXACT_LINES,
        loop_closure=LoopClosureConfig(confirmations=1, judge_unconfirmed=False),
    )
    slam, _, _ = run_slam(run, config)
    attempts = slam.loop_closer.attempts
    waited = [e for e in attempts if e.kind == "gated" and "second" in (e.reason or "")]
    judged = [e for e in attempts if e.kind == "judged"]
    assert waited and judged and slam.counters["loop_closures"] >= 1
    # each judged hypothesis came after one that waited
    assert min(e.keyframe for e in waited) < min(e.keyframe for e in judged)


def test_a_hypothesis_waiting_alone_is_judged_late_or_replaced(loop_runs):
    """``judge_unconfirmed``: every hypothesis that waits for a second one is settled at the
    next attempt: judged with the one that agrees with it, replaced by a newer one that does
    not, or judged on its own (``judged_late``) by an attempt that found no new hypothesis;
    the loop is closed as well as without waiting."""
    _, path, run, _ = loop_runs
    lcc = LoopClosureConfig(confirmations=1, judge_unconfirmed=True, judge_replaced=False)
    slam, res, _ = run_slam(run, SlamConfig(motion=MOTION, **EXACT_LINES, loop_closure=lcc))
    attempts = slam.loop_closer.attempts
    waited = [e for e in attempts if e.kind == "gated" and (e.reason or "").startswith("await")]
    assert waited and slam.counters["loop_closures"] >= 1
    judged = [e for e in attempts if e.kind == "judged"]
    assert slam.counters["loop_closure_candidates"] == len(judged)
    for i, e in enumerate(attempts):
        if not (e.kind == "gated" and (e.reason or "").startswith("awaiting")):
            continue
        rest = attempts[i + 1 :]
        nxt = next((a for a in rest if a.keyframe > e.keyframe or a.judged_late), None)
        if nxt is None:  # the run ended: judged at its end
            continue
        if nxt.judged_late:
            # judged by an attempt that found nothing new: no hypothesis at that keyframe
            assert nxt.keyframe == e.keyframe and nxt.judged_at_keyframe > e.keyframe
            at = [a for a in attempts if a.keyframe == nxt.judged_at_keyframe]
            assert all(a.kind in ("not_found", "repeated") for a in at)
        elif nxt.kind == "judged":
            assert nxt.agreeing_hypotheses >= 1
        else:
            assert nxt.kind == "gated"
            if (nxt.reason or "").startswith("awaiting"):
                assert f"since keyframe {e.keyframe}," in nxt.reason
    err = pose_log(pose_between(path, res.poses_world_laser))
    assert np.sqrt(np.mean(np.sum(err[:, :2] ** 2, axis=1))) < 0.08


def test_waiting_hypothesis_bookkeeping(monkeypatch):
    """The gate keeps the newest unconfirmed hypothesis, drops it once one agrees, leaves it
    alone when a hypothesis contradicts an accepted closure; an attempt that finds nothing
    judges it (late, at that attempt's keyframe), and so does the end of the run."""
    from slam.line_slam.loop_closer import Hypothesis, _Pending

    lcc = LoopClosureConfig(confirmations=1, judge_unconfirmed=True, judge_replaced=False)
    slam = LineSlam(SlamConfig(loop_closure=lcc))
    closer = slam.loop_closer
    contradicts: list[str | None] = [None]
    monkeypatch.setattr(closer, "contradiction", lambda h: contradicts[0])

    def candidate(k):
        return _Pending(np.arange(2), np.arange(2), None, 0.0, Hypothesis(k, 0, np.zeros(3)))

    first, second = candidate(10), candidate(15)
    assert closer.gate(first, 0).startswith("awaiting") and closer.waiting is first.hypothesis
    reason = closer.gate(second, 0)
    assert "since keyframe 10," in reason and closer.waiting is second.hypothesis
    contradicts[0] = "contradicts the closure accepted at keyframe 12"
    assert closer.gate(candidate(20), 0) == contradicts[0]
    assert closer.waiting is second.hypothesis
    contradicts[0] = None
    assert closer.gate(candidate(20), 1) is None and closer.waiting is None
    # attempts: one that finds nothing judges the waiting hypothesis, one that finds one not
    judged = []
    monkeypatch.setattr(closer, "apply", lambda *a, **k: judged.append((a, k)) or 1)
    finds = []

    def fake_attempt(pose):
        if finds.pop(0):
            closer.attempts.append(ClosureAttempt("gated", pose, reason="awaiting"))
        else:
            closer.attempts.append(ClosureAttempt("not_found", pose))
        return 0

    from slam.line_slam.loop_closer import ClosureAttempt

    monkeypatch.setattr(closer, "_attempt", fake_attempt)
    closer.gate(first, 0)
    finds[:] = [True, False]
    assert closer.attempt(15) == 0 and not judged
    assert closer.attempt(20) == 1 and closer.waiting is None
    ((args, kwargs),) = judged
    assert args[3] == 10 and kwargs == {"late": True, "judged_at": 20}
    closer.gate(second, 0)
    assert closer.judge_pending() == 1 and judged[-1][1] == {"late": True, "judged_at": None}
    assert closer.judge_pending() == 0 and len(judged) == 2
    # without judge_unconfirmed nothing waits to be judged
    lcc = LoopClosureConfig(confirmations=1, judge_unconfirmed=False)
    slam = LineSlam(SlamConfig(loop_closure=lcc))
    monkeypatch.setattr(slam.loop_closer, "contradiction", lambda h: None)
    assert slam.loop_closer.gate(first, 0).startswith("awaiting")
    assert slam.loop_closer.waiting is None


@pytest.mark.parametrize("accepted", [0, 1])
def test_replaced_hypothesis_is_judged(monkeypatch, accepted):
    """``judge_replaced``: the waiting hypothesis that a newer one replaces is judged (late) by
    the attempt that found the newer one; accepted, it drops the newer one (its log entry says
    so); rejected, the newer one waits.  Without the setting the replaced one is dropped."""
    from slam.line_slam.loop_closer import ClosureAttempt, Hypothesis, _Pending

    def candidate(k):
        return _Pending(np.arange(2), np.arange(2), None, 0.0, Hypothesis(k, 0, np.zeros(3)))

    for judge_replaced in (True, False):
        lcc = LoopClosureConfig(
            confirmations=1, judge_unconfirmed=True, judge_replaced=judge_replaced
        )
        slam = LineSlam(SlamConfig(loop_closure=lcc))
        closer = slam.loop_closer
        monkeypatch.setattr(closer, "contradiction", lambda h: None)
        judged: list = []

        def fake_apply(*a, judged=judged, **k):
            judged.append((a, k))
            return accepted

        monkeypatch.setattr(closer, "apply", fake_apply)
        first, second = candidate(10), candidate(15)

        def fake_attempt(pose, closer=closer, second=second):
            reason = closer.gate(second, 0)
            closer.attempts.append(ClosureAttempt("gated", pose, reason=reason))
            return 0

        monkeypatch.setattr(closer, "_attempt", fake_attempt)
        closer.gate(first, 0)
        got = closer.attempt(15)
        entry = closer.attempts[-1]
        assert "since keyframe 10," in entry.reason
        if not judge_replaced:
            assert got == 0 and not judged and closer.waiting is second.hypothesis
            continue
        ((args, kwargs),) = judged
        assert args[3] == 10 and kwargs == {"late": True, "judged_at": 15}
        assert got == accepted
        if accepted:
            assert closer.waiting is None and entry.reason.endswith(
                "the one it replaced was accepted"
            )
        else:
            assert closer.waiting is second.hypothesis and "dropped" not in entry.reason


@pytest.mark.parametrize(("same_place", "expected"), [(False, [0, 1, 2]), (True, [0, 1, 0])])
def test_agreement_of_the_same_revisit(monkeypatch, same_place, expected):
    """With ``agreement_same_place`` a hypothesis onto old keyframes 200 keyframes away from
    another's does not count as agreeing with it, whatever their pairwise test says."""
    from slam.line_slam.loop_closer import Hypothesis

    lcc = LoopClosureConfig(agreement_same_place=same_place)
    closer = LineSlam(SlamConfig(loop_closure=lcc)).loop_closer
    monkeypatch.setattr(closer, "pair_chi2", lambda a, b: 0.0)  # every pair consistent
    got = [
        closer.agreement(Hypothesis(k, k_old, np.zeros(3)))
        for k, k_old in ((300, 100), (305, 110), (310, 310))
    ]
    assert got == expected


def test_map_lines_match_the_true_walls(loop_runs):
    """Every map line runs along a true wall piece (its ends within 6 cm of the line, normals
    within 0.5°), each of its visible segments lies on such a piece (± 0.3 m), and the lines'
    errors are consistent with their covariances."""
    world, _, _, out = loop_runs
    _, res, _ = out["isam2"]
    walls = world.wall_lines()
    matched_walls = set()
    for la, segs in zip(res.landmarks_r_alpha, res.landmark_segments, strict=True):
        n = np.array([np.cos(la[1]), np.sin(la[1])])
        d_alpha = np.abs(np.angle(np.exp(1j * (walls[:, 1] - la[1]))))
        d_alpha = np.minimum(d_alpha, np.pi - d_alpha)
        dist = np.abs(world.walls @ n - la[0]).max(axis=1)  # both ends of each wall piece
        on_line = np.flatnonzero((dist < 0.06) & (d_alpha < np.deg2rad(0.5)))
        assert on_line.size, (la, dist.min())
        for seg in segs:
            inside = []
            for w in on_line:
                a, b = world.walls[w]
                t = (b - a) / np.linalg.norm(b - a)
                sv = (seg - a) @ t
                inside.append(sv.min() > -0.3 and sv.max() < np.linalg.norm(b - a) + 0.3)
            assert any(inside)
            matched_walls.update(int(w) for w, ok in zip(on_line, inside, strict=True) if ok)
    assert len(matched_walls) >= 0.8 * len(world.walls)  # nearly every wall piece is mapped
    # normalised errors of the map lines against their walls: about χ²₂ on average
    d2 = []
    for la, P in zip(res.landmarks_r_alpha, res.landmark_covariances, strict=True):
        k = np.argmin(
            np.abs(walls[:, 0] - la[0]) + 5 * np.abs(np.angle(np.exp(1j * (walls[:, 1] - la[1]))))
        )
        e = np.array([la[0] - walls[k, 0], np.angle(np.exp(1j * (la[1] - walls[k, 1])))])
        d2.append(e @ np.linalg.solve(P, e))
    assert np.mean(d2) < 2.0 * 2.5 and np.median(d2) < 2.0 * 1.5
    # landmarks are in normal form, covariances positive definite
    assert np.all(res.landmarks_r_alpha[:, 0] >= 0)
    assert np.all(np.linalg.eigvalsh(res.landmark_covariances) > 0)


def test_batch_backend_is_as_accurate(loop_runs):
    """Periodic batch solves (every 5 keyframes) on the same data: same accuracy class."""
    _, path, _, out = loop_runs
    (_, res_i, _), (_, res_b, _) = out["isam2"], out["batch"]
    np.testing.assert_allclose(
        res_i.poses_world_laser[:, :2], res_b.poses_world_laser[:, :2], atol=0.02
    )
    err_b = np.hypot(*(res_b.poses_world_laser[:, :2] - path[:, :2]).T)
    assert np.sqrt(np.mean(err_b**2)) < 0.08


def test_batch_and_isam2_agree_on_the_same_data():
    """With a solve per keyframe the batch back-end sees the same estimates and covariances as
    iSAM2 when associating: identical associations, and the same final solution.  A property of
    the least-squares model: with a robust kernel the two weight by different rules (IRLS per
    batch iteration, per block rebuild in iSAM2), so the Gaussian cost is stated."""
    gaussian = SolverConfig(robust_kernel="none")
    world = corridor_loop(length=10.0, width=6.0, piece=3.0, door=1.0)
    path = loop_path(10, 6, 0.5, laps=0.6)
    run = simulate_run(world, path, seed=9, motion=MOTION)
    _, res_i, rep_i = run_slam(run, SlamConfig(motion=MOTION, solver=gaussian, **EXACT_LINES))
    _, res_b, rep_b = run_slam(
        run, SlamConfig(backend="batch", motion=MOTION, solver=gaussian, **EXACT_LINES)
    )
    assert [(r.matched, r.new_landmarks) for r in rep_i] == [
        (r.matched, r.new_landmarks) for r in rep_b
    ]
    np.testing.assert_allclose(
        res_i.poses_world_laser[:, :2], res_b.poses_world_laser[:, :2], atol=2e-3
    )
    np.testing.assert_allclose(res_i.landmarks_r_alpha, res_b.landmarks_r_alpha, atol=2e-3)
    d = np.sqrt(np.einsum("nii->ni", res_b.pose_covariances))
    assert np.all(
        np.abs(res_i.pose_covariances - res_b.pose_covariances)
        <= 0.03 * d[:, :, None] * d[:, None, :]
    )


def test_pose_nees_within_chi2_bounds_monte_carlo():
    """Average NEES of the laser pose over seeded runs of a short loop (3 dof)."""
    world = corridor_loop(length=10.0, width=6.0, piece=3.0, door=1.0)
    path = loop_path(10, 6, 0.5, laps=1.0)
    nees = []
    for seed in range(6):
        run = simulate_run(world, path, seed=200 + seed, motion=MOTION)
        _, res, _ = run_slam(run, SlamConfig(motion=MOTION, **EXACT_LINES))
        e = pose_log(pose_between(path, res.poses_world_laser))
        n = np.einsum("ni,nij,nj->n", e, np.linalg.inv(res.pose_covariances), e)
        nees.append(n[5::10])  # spaced poses of each run
    nees = np.concatenate(nees)
    # χ²₃ mean 3; 6 runs × 7 spaced (correlated) poses: a 99 % band for ~15 independent ones
    assert 3.0 * 0.45 < nees.mean() < 3.0 * 1.8
    assert np.mean(nees > 11.34) < 0.1  # χ²₃(0.99): few outliers


def test_scan_without_lines_warns_and_rests_on_odometry():
    world = corridor_loop(length=10.0, width=6.0, piece=3.0, door=1.0)
    path = loop_path(10, 6, 0.5, laps=0.5)
    run = simulate_run(world, path, seed=5, motion=MOTION)
    lines = [list(ls) for ls in run.lines]
    for k in (10, 11, 12):
        lines[k] = []
    slam = LineSlam(SlamConfig(motion=MOTION, **EXACT_LINES))
    with pytest.warns(SlamWarning, match="without usable lines"):
        for s, ls in zip(run.scans, lines, strict=True):
            rep = slam.add_scan(s, ls)
            if s.index in (10, 11, 12):
                assert rep.warnings == (WARN_NO_LINES,)
    slam.optimize()
    res = slam.result()
    assert slam.counters["keyframes_without_lines"] == 3
    err = np.hypot(*(res.poses_world_laser[:, :2] - path[:, :2]).T)
    assert np.isfinite(res.pose_covariances).all() and err.max() < 0.1
    # the blind poses are less certain than their neighbours
    tr = np.einsum("nii->n", res.pose_covariances[:, :2, :2])
    assert tr[11] > tr[8]


def test_parallel_walls_warn_and_the_position_along_them_follows_odometry():
    world = straight_corridor(length=40.0)
    path = np.column_stack([np.arange(0.0, 30.0, 0.4), np.zeros(75), np.zeros(75)])
    run = simulate_run(world, path, seed=6, motion=MOTION)
    slam = LineSlam(SlamConfig(motion=MOTION, **EXACT_LINES))
    with pytest.warns(SlamWarning, match="parallel"):
        reports = [slam.add_scan(s, ls) for s, ls in zip(run.scans, run.lines, strict=True)]
    slam.optimize()
    res = slam.result()
    assert sum(WARN_PARALLEL in r.warnings for r in reports) > 60
    err = res.poses_world_laser - path
    odo_err = run.odometry - path
    # across the corridor and in heading the walls correct the drift (what is left is the
    # walls' own angle, known from the first scans: consistent with the covariance) ...
    sy = np.sqrt(res.pose_covariances[:, 1, 1])
    assert np.all(np.abs(err[:, 1]) < 3.5 * sy) and np.abs(err[:, 2]).max() < 0.01
    assert np.abs(err[:, 1]).max() < 0.3 * np.abs(odo_err[:, 1]).max()
    # ... along it nothing can: the estimate keeps the odometry's forward error, and says so
    rel_true = pose_between(path[:-1], path[1:])
    rel_odo = pose_between(run.odometry[:-1], run.odometry[1:])
    forward_err = np.r_[0.0, np.cumsum(rel_odo[:, 0] - rel_true[:, 0])]
    assert np.abs(forward_err).max() > 0.1
    np.testing.assert_allclose(err[:, 0], forward_err, atol=0.03)
    sx = np.sqrt(res.pose_covariances[:, 0, 0])
    odo_var = MOTION.covariance(rel_true)[:, 0, 0]
    np.testing.assert_allclose(sx[1:], np.sqrt(np.cumsum(odo_var)), rtol=0.1)


def test_lost_association_warns_starts_landmarks_and_recovers():
    world = corridor_loop(length=10.0, width=6.0, piece=3.0, door=1.0)
    path = loop_path(10, 6, 0.5, laps=0.75)
    run = simulate_run(world, path, seed=7, motion=MOTION)
    lines = [list(ls) for ls in run.lines]
    # scan 15 sees something else entirely (a reflection, a crowd): two lines far off
    lines[15] = [_line(3.5, 0.8), _line(4.0, 2.4)]
    slam = LineSlam(SlamConfig(motion=MOTION, **EXACT_LINES, fusion=FusionConfig(enabled=False)))
    with pytest.warns(SlamWarning, match="lost association"):
        reports = [slam.add_scan(s, ls) for s, ls in zip(run.scans, lines, strict=True)]
    assert reports[15].warnings == (WARN_LOST,) and reports[15].new_landmarks == 2
    assert all(r.matched > 0 for r in reports[16:])
    slam.optimize()
    res = slam.result()
    err = np.hypot(*(res.poses_world_laser[:, :2] - path[:, :2]).T)
    assert err.max() < 0.1


def _line(r: float, alpha: float) -> Line:
    cov = np.diag([1e-4, 4e-6, 0.01])
    return Line(r, alpha, 0.0, cov, np.array([[-1.0, 1.0]]), np.full((1, 2), 1e-4), 100)


def test_keyframes_and_result_round_trip(tmp_path):
    world = corridor_loop(length=10.0, width=6.0, piece=3.0, door=1.0)
    path = loop_path(10, 6, 0.1, laps=0.3)
    run = simulate_run(world, path, seed=8, motion=MOTION)
    cfg = SlamConfig(
        motion=MOTION,
        **EXACT_LINES,
        keyframes=KeyframeConfig(min_distance_m=0.5, min_angle_rad=0.3),
    )
    _, res, reports = run_slam(run, cfg)
    kf = np.array([r.keyframe for r in reports])
    assert kf[0] and 0.1 < kf.mean() < 0.35
    assert res.n_scans == len(run.scans) and res.is_keyframe.tolist() == kf.tolist()
    # non-keyframe poses are their keyframe's pose composed with the odometry since, with the
    # odometry's noise added to the covariance: errors consistent with it everywhere
    err = np.hypot(*(res.poses_world_laser[:, :2] - path[:, :2]).T)
    assert err[kf].max() < 0.05
    e = pose_log(pose_between(path, res.poses_world_laser))
    nees = np.einsum("ni,nij,nj->n", e, np.linalg.inv(res.pose_covariances), e)
    assert nees.max() < 16.27 and nees.mean() < 3 * 1.6
    doc = json.loads(json.dumps(res.to_json_dict()))
    back = SlamResult.from_json_dict(doc)
    np.testing.assert_array_equal(back.poses_world_laser, res.poses_world_laser)
    np.testing.assert_array_equal(back.landmark_covariances, res.landmark_covariances)
    assert [s.shape for s in back.landmark_segments] == [s.shape for s in res.landmark_segments]
    summary = res.summary_dict()
    assert summary["scans"] == len(run.scans) and summary["frame"] == "laser"
    assert summary["keyframes"] == int(kf.sum())


def test_scan_without_odometry_is_an_input_error():
    slam = LineSlam()
    scan = Scan(index=0, timestamp=0.0, ranges=np.zeros(0), bearings=np.zeros(0), source="x.clf:3")
    with pytest.raises(InputError, match=r"x\.clf:3.*odometry"):
        slam.add_scan(scan, [])


def test_rejected_loop_closure_leaves_graph_and_backend_untouched(loop_runs):
    """A candidate the judge rejects is rolled back before the back-end sees it."""
    from slam.frontend.loop_closure import LoopClosure

    slam = loop_runs[3]["isam2"][0]
    g = slam.graph
    alive = np.flatnonzero(g.landmark_alive)
    alpha = g.landmarks_r_alpha[alive, 1]
    # pair walls with walls about 90° away: four "matches" no estimate can explain
    a = alive[np.abs(np.cos(alpha)) > 0.9][:4]
    b = alive[np.abs(np.sin(alpha)) > 0.9][:4]
    assert a.size == b.size == 4
    pose = g.n_poses - 1
    found = LoopClosure(np.array([0.3, -0.2, 0.02]), [(k, k) for k in range(4)], 10.0, 1.0)
    state = (g.poses.copy(), g.landmarks.copy(), g.factor_landmark.copy(), len(g.merge_log))
    updates = slam.backend.solver.stats.updates
    undone = slam.counters["loop_closures_undone"]
    candidates = slam.counters["loop_closure_candidates"]
    assert slam.loop_closer.apply(a, b, found, pose) == 0
    assert slam.counters["loop_closures_undone"] == undone + 1
    assert slam.counters["loop_closure_candidates"] == candidates + 1  # judged
    assert slam.loop_closer.attempts[-1].accepted is False
    np.testing.assert_array_equal(g.poses, state[0])
    np.testing.assert_array_equal(g.landmarks, state[1])
    np.testing.assert_array_equal(g.factor_landmark, state[2])
    assert len(g.merge_log) == state[3]
    assert slam.backend.solver.stats.updates == updates
    # the same hypothesis found again shortly after, with no more pairs, is not judged again;
    # with more pairs, another correction, or once the local submap has moved on, it is
    lcc = slam.config.loop_closure
    assert slam.loop_closer.repeated_rejection(found, pose + 1) == pose
    nearby = LoopClosure(found.correction + [0.1, 0.0, 0.01], found.pairs, 10.0, 1.0)
    assert slam.loop_closer.repeated_rejection(nearby, pose + 1) == pose
    more = LoopClosure(found.correction, [(k, k) for k in range(5)], 12.0, 1.0)
    assert slam.loop_closer.repeated_rejection(more, pose + 1) is None
    other = LoopClosure(found.correction + [0.5, 0.0, 0.0], found.pairs, 10.0, 1.0)
    assert slam.loop_closer.repeated_rejection(other, pose + 1) is None
    assert slam.loop_closer.repeated_rejection(found, pose + lcc.local_keyframes) is None


def _undone_merges_and_a_wrong_pair(seed=3):
    """A simulated loop's last three fusion merges undone (three right pairs: each a wall seen
    as two landmarks) and a wrong pair (a well-observed landmark and one about 90° from it)."""
    world = corridor_loop(piece=3.0, door=1.0)
    path = loop_path(16, 8, 0.4, laps=1.25)
    run = simulate_run(world, path, seed=seed, motion=MOTION)
    slam, _, _ = run_slam(run, SlamConfig(motion=MOTION, **EXACT_LINES))
    g = slam.graph
    records = [
        r
        for r in g.merge_log
        if not r.undo and not g.landmark_alive[r.drop] and g.landmark_alive[r.keep]
    ]
    records = [r for r in records if np.count_nonzero(g.factor_landmark == r.keep) > r.factors.size]
    right = records[-3:]
    assert len(right) == 3
    for rec in right:
        g.unmerge(rec)
    slam.book.recompute_info(np.array([i for r in right for i in (r.keep, r.drop)]))
    slam.backend.update(g)
    slam.backend.optimize(g)
    slam.book.refresh_extents()
    counts = g.observation_counts()
    used = {i for r in right for i in (r.keep, r.drop)}
    alive = [int(j) for j in np.flatnonzero(g.landmark_alive) if j not in used and counts[j] >= 3]
    alpha = g.landmarks_r_alpha[:, 1]
    a = alive[0]
    b = next(j for j in alive if abs(np.cos(alpha[j] - alpha[a])) < 0.2)
    return slam, right, (a, b)


def _judge(with_wrong_pair, agree=0, seed=3, bend_m=0.0, before_judging=None, **loop_closure):
    """The three right pairs (and the wrong one) judged as one closure with the loop-closure
    settings changed by ``loop_closure``, ``agree`` recent hypotheses agreeing; returns
    ``(accepted, log entry)``.  ``bend_m``: the second half of the trajectory bent sideways by
    up to that much first (the estimate the judge starts from is then not the loop's optimum).
    ``before_judging``: called once the loop is built, right before the judgement."""
    from slam.frontend.loop_closure import LoopClosure

    slam, right, (a, b) = _undone_merges_and_a_wrong_pair(seed)
    if bend_m:
        poses = slam.graph.poses
        half = poses.shape[0] // 2
        poses[half:, 1] += bend_m * np.linspace(0.0, 1.0, poses.shape[0] - half)
    lcc = replace(slam.config.loop_closure, **loop_closure)
    slam.loop_closer.config = replace(slam.config, loop_closure=lcc)
    local = [r.drop for r in right] + ([a] if with_wrong_pair else [])
    old = [r.keep for r in right] + ([b] if with_wrong_pair else [])
    found = LoopClosure(np.zeros(3), [(k, k) for k in range(len(local))], 10.0, 1.0)
    if before_judging is not None:
        before_judging()
    got = slam.loop_closer.apply(
        np.array(local), np.array(old), found, slam.graph.n_poses - 1, agree=agree
    )
    return got, slam.loop_closer.attempts[-1].as_log()


def _with_wrong_closure():
    """The fixture's loop with its wrong pair merged and converged, registered as a closure
    accepted five keyframes ago whose hypothesis lies 3 m off the front end's trajectory; and
    the three right pairs as a hypothesis on that trajectory."""
    from slam.frontend.loop_closure import LoopClosure
    from slam.geometry import pose_compose
    from slam.line_slam.loop_closer import Hypothesis, _Accepted

    slam, right, (a, b) = _undone_merges_and_a_wrong_pair()
    g, closer = slam.graph, slam.loop_closer
    n_log = len(g.merge_log)
    slam.book.merge(b, a)
    wrong_record = g.merge_log[n_log]
    slam.backend.update(g)
    slam.backend.optimize(g)
    slam.book.refresh_extents()
    pose = g.n_poses - 1
    k_old = 5
    chain = closer.drift.relative(k_old, pose)
    off = Hypothesis(pose - 5, k_old, pose_compose(chain, np.array([3.0, 0.0, 0.0])))
    closer._accepted = [_Accepted(off, 50.0, [wrong_record])]  # the only one
    h = Hypothesis(pose, k_old, chain)
    found = LoopClosure(np.zeros(3), [(k, k) for k in range(3)], 10.0, 1.0)
    local = np.array([r.drop for r in right])
    old = np.array([r.keep for r in right])
    return slam, (a, b), h, found, local, old


def _reconsidering(slam, n=20):
    lcc = replace(slam.config.loop_closure, reconsider_keyframes=n)
    slam.loop_closer.config = replace(slam.config, loop_closure=lcc)


def test_a_recent_closure_is_reconsidered_only_by_a_hypothesis_that_disagrees_and_fits_better():
    """``rival``: the accepted closure is a rival of a hypothesis that agrees with the front
    end's trajectory (χ² 0 < its 50) and not with it (3 m apart), and that one recent
    hypothesis agrees with (none agreed with the closure); not when the hypothesis' own χ² is
    beyond the quantile or above the closure's, not when no more hypotheses agree with it than
    with the closure, not when the two agree, not when the closure is older than
    ``reconsider_keyframes`` (no limit by default) or when that is 0."""
    slam, _, h, *_ = _with_wrong_closure()
    closer = slam.loop_closer
    rival = closer._accepted[0]
    assert slam.config.loop_closure.reconsider_keyframes is None
    assert closer.rival(h, 0.0, 1) is rival  # on by default
    _reconsidering(slam, 0)
    assert closer.rival(h, 0.0, 1) is None  # off
    _reconsidering(slam)
    assert closer.rival(h, 0.0, 1) is rival
    assert closer.rival(h, 60.0, 1) is None  # beyond the quantile (and above the closure's)
    assert closer.rival(h, 0.0, 0) is None  # no more hypotheses agree with it than with the closure
    closer._accepted[0] = replace(rival, chain_chi2=0.0)
    assert closer.rival(h, 0.0, 1) is None  # the closure fitted the trajectory as well
    z = closer.drift.relative(h.k_old, rival.keyframe)  # on the front end's trajectory
    agreeing = replace(rival.hypothesis, z=z)
    closer._accepted[0] = replace(rival, hypothesis=agreeing)
    assert closer.rival(h, 0.0, 1) is None  # the two agree
    closer._accepted[0] = rival
    _reconsidering(slam, 4)
    assert closer.rival(h, 0.0, 1) is None  # accepted 5 keyframes before h
    _reconsidering(slam, 5)
    assert closer.rival(h, 0.0, 1) is rival
    # however long ago, by default: the closure is kept for it, not forgotten
    _reconsidering(slam, None)
    assert closer._recent_accepted(h.keyframe + 10_000, None) == [rival]
    assert closer._recent_accepted(h.keyframe + 10_000, 5) == []


def test_reconsider_keyframes_reads_from_a_config_file(tmp_path):
    """Left out: no limit (None, also after the run's config.toml is read back); a number
    of keyframes or 0 (never) as written; a negative one is an error naming the key."""
    assert RunConfig().slam.loop_closure.reconsider_keyframes is None
    path = tmp_path / "run.toml"
    RunConfig().to_toml(path)
    assert RunConfig.from_toml(path).slam.loop_closure.reconsider_keyframes is None
    for n in (0, 20):
        path.write_text(f"[slam.loop_closure]\nreconsider_keyframes = {n}\n")
        assert RunConfig.from_toml(path).slam.loop_closure.reconsider_keyframes == n
    path.write_text("[slam.loop_closure]\nreconsider_keyframes = -1\n")
    with pytest.raises(ConfigError, match="reconsider_keyframes"):
        RunConfig.from_toml(path)


@pytest.mark.parametrize("accepted", [True, False])
def test_reconsidering_a_closure_drops_it_or_leaves_everything_as_it_was(accepted):
    """The right pairs judged with the wrong closure's merge undone.  Accepted (a permissive
    judge): the wrong pair is apart again and vetoed, the right pairs merged, the closure
    dropped, counted and no longer turning hypotheses away, what it measured of the graph's
    covariance gone from the graph gate's scale, the judgement logged with the dropped
    closure's keyframe.  Rejected (a judge that accepts nothing): the graph, the estimate,
    the merge log and the scale are exactly as before, the closure still accepted."""
    slam, (a, b), h, found, local, old = _with_wrong_closure()
    g, closer = slam.graph, slam.loop_closer
    # the graph gate's record: the wrong closure's χ² beside a right one's (3 dof each)
    S, C = np.eye(3) * 1e-4, np.eye(3) * 1e-12
    wrong = _graph_test_of(np.full(3, np.sqrt(300 * 1e-4)), S, C)
    right = _graph_test_of(np.full(3, np.sqrt(2 * 1e-4)), S, C)
    rival = replace(closer._accepted[0], graph=wrong)
    closer._accepted[0] = rival
    closer._graph_tests = [right, wrong]
    # an observation added to the merged landmark since the merge (the current pass's: a copy
    # of one of the dropped landmark's) goes back with the merge
    f = int(rival.records[0].factors[-1])
    later = g.add_line_factors(
        int(g.factor_pose[f]),
        np.array([b]),
        g.factor_z[[f]],
        g.factor_cov[[f]],
        g.factor_endpoints[[f]],
    )
    slam.backend.update(g)
    limit = np.inf if accepted else 1e-9  # no pair is explained to within 1e-9
    lcc = replace(
        slam.config.loop_closure,
        judge_max_f=np.inf,
        judge_max_pair_chi2=limit,
        reconsider_keyframes=20,
    )
    closer.config = replace(slam.config, loop_closure=lcc)
    before = (g.factor_landmark.copy(), g.landmark_alive.copy(), g.poses.copy(), len(g.merge_log))
    got = closer.reconsider(rival, local, old, found, g.n_poses - 1, 0.0, 0, h)
    entry = closer.attempts[-1].as_log()
    assert entry["reconsidered_closure"] == rival.keyframe
    if accepted:
        assert got == 1 and entry["accepted"]
        assert g.landmark_alive[a] and g.landmark_alive[b]
        assert np.all(g.factor_landmark[later] == a)
        assert (min(a, b), max(a, b)) in closer.audit.vetoed
        assert not np.any(g.landmark_alive[local])  # the right pairs merged
        assert slam.counters["loop_closures_dropped"] == 1
        assert rival not in closer._accepted
        # the reconsidering hypothesis is not tested against the graph: only the right one left
        assert closer.graph_report()["dof"] == 3
        assert closer.graph_report()["chi2_per_dof"] == pytest.approx(2.0)
    else:
        assert got == 0 and not entry["accepted"]
        np.testing.assert_array_equal(g.factor_landmark, before[0])
        np.testing.assert_array_equal(g.landmark_alive, before[1])
        np.testing.assert_array_equal(g.poses, before[2])
        assert len(g.merge_log) == before[3] and not g.landmark_alive[a]
        assert np.all(g.factor_landmark[later] == b)
        assert slam.counters["loop_closures_dropped"] == 0
        assert rival in closer._accepted
        assert closer.graph_report()["dof"] == 6
        assert closer.graph_report()["chi2_per_dof"] == pytest.approx(151.0)


def _moved(x, corr):
    """Keyframe pose ``x`` moved by a correction ``(t_x, t_y, dθ)`` (about its position)."""
    return np.array([x[0] + corr[0], x[1] + corr[1], x[2] + corr[2]])


def test_a_hypothesis_asks_the_current_estimate_for_its_relative_pose():
    """``correction_at`` is the inverse of ``hypothesis``: the correction a hypothesis was made
    from comes back, and when the estimate moves, the correction moves with it so that the
    two keyframes again stand at the hypothesis' relative pose ``z``."""
    slam, _, h, found, _, old = _with_wrong_closure()
    g, closer = slam.graph, slam.loop_closer
    made = replace(found, correction=np.array([0.3, -0.2, 0.05]))
    h = closer.hypothesis(made, old, h.keyframe, h.k_old)
    np.testing.assert_allclose(
        closer.correction_at(h), closer.effective_correction(made, old), atol=1e-12
    )
    g.poses[h.keyframe] += np.array([0.5, 0.1, 0.02])
    g.poses[h.k_old] += np.array([-0.2, 0.3, -0.01])
    corr = closer.correction_at(h)
    moved = _moved(g.poses[h.keyframe], corr)
    np.testing.assert_allclose(
        pose_log(pose_between(h.z, pose_between(g.poses[h.k_old], moved))), 0.0, atol=1e-12
    )


def test_reconsidering_reads_the_correction_at_the_estimate_without_the_closure(monkeypatch):
    """The hypothesis found with the wrong closure in place is judged again, with the closure
    undone and the loops solved, from the correction that puts its two keyframes at its
    relative pose on that estimate (not the correction read on the estimate the closure had
    shaped, which the solve without the closure has moved)."""
    slam, _, h, found, local, old = _with_wrong_closure()
    g, closer = slam.graph, slam.loop_closer
    rival = closer._accepted[0]
    h = closer.hypothesis(
        replace(found, correction=np.array([0.3, -0.2, 0.05])), old, h.keyframe, h.k_old
    )
    seen = []

    def judged(local, old, f, pose, *args, **kwargs):
        moved = _moved(g.poses[h.keyframe], closer.effective_correction(f, old))
        seen.append((pose_between(g.poses[h.k_old], moved), g.poses.copy()))
        return 0

    monkeypatch.setattr(closer, "apply", judged)
    before = g.poses.copy()
    assert closer.reconsider(rival, local, old, found, h.keyframe, 0.0, 0, h) == 0
    ((z_seen, poses_seen),) = seen
    assert np.max(np.abs(poses_seen - before)) > 1e-3  # the loops were solved without the closure
    np.testing.assert_allclose(pose_log(pose_between(h.z, z_seen)), 0.0, atol=1e-9)


def test_a_rejected_hypothesis_reconsiders_the_closure_it_contradicts(monkeypatch):
    """Through ``apply``: a hypothesis the judge rejects reconsiders its rival (the wrong
    closure) once; one that is accepted, or judged while reconsidering, does not."""
    slam, _, h, found, local, old = _with_wrong_closure()
    closer = slam.loop_closer
    rival = closer._accepted[0]
    calls = []
    monkeypatch.setattr(closer, "reconsider", lambda r, *args: calls.append(r) or 0)
    lcc = replace(
        slam.config.loop_closure,
        judge_max_f=np.inf,
        judge_max_pair_chi2=1e-9,  # no pair is explained
        reconsider_keyframes=20,
    )
    closer.config = replace(slam.config, loop_closure=lcc)
    pose = slam.graph.n_poses - 1
    assert closer.apply(local, old, found, pose, 0.0, 1, h) == 0
    assert calls == [rival]
    assert closer.apply(local, old, found, pose, 0.0, 1, h, reconsidering=rival) == 0
    assert calls == [rival]
    lcc = replace(lcc, judge_max_pair_chi2=np.inf)
    closer.config = replace(closer.config, loop_closure=lcc)
    assert closer.apply(local, old, found, pose, 0.0, 1, h) == 1
    assert calls == [rival]


@pytest.mark.parametrize(
    ("max_pair_chi2", "max_f", "accepted"),
    [(np.inf, np.inf, 1), (1000.0, np.inf, 0), (np.inf, 100.0, 0)],
)
def test_closure_with_a_pair_left_metres_apart_is_rejected_whole(max_pair_chi2, max_f, accepted):
    """Three right pairs and one pairing a wall with a perpendicular one: the fraction rule
    (3 of 4 explained) accepts it; ``judge_max_pair_chi2`` rejects it whole, and so does the F
    test of the merged loop against its own residual level (``judge_max_f``)."""
    got, entry = _judge(True, judge_max_pair_chi2=max_pair_chi2, judge_max_f=max_f)
    assert entry["consistent_pairs"] == 3 and entry["worst_pair_chi2"] > 1000.0
    assert entry["f_statistic"] > 100.0
    assert got == accepted


def test_right_closure_passes_the_f_test():
    """The same three right pairs without the wrong one: the merged loop's cost per merged
    degree of freedom stays at the graph's own level (F well below ``judge_max_f``)."""
    got, entry = _judge(False)
    assert got == 1
    assert entry["f_statistic"] < 10.0


def test_robust_second_chance_needs_every_pair_explained_and_an_agreeing_hypothesis():
    """``judge_robust_cost``: a closure that fails the Gaussian F test but passes it in the
    solver's robust cost is accepted only with all its pairs explained and a recent hypothesis
    agreeing with it; a closure with a pair left metres apart is not, whatever its robust F.

    Which of the two F statistics of three right pairs is the larger depends on the loop's
    residuals (over seeds 1-8 of this loop the robust one is the smaller in six); the loop of
    seed 4 has the robust F at half the Gaussian one, the case the second chance is for."""
    _, entry = _judge(False, seed=4, judge_robust_cost=True, judge_max_f=np.inf)
    f_gauss, f_robust = entry["f_statistic"], entry["f_statistic_robust"]
    assert entry["consistent_pairs"] == entry["pairs"] == 3
    assert 0.0 < f_robust < f_gauss  # the premise: the robust cost grew less
    between = 0.5 * (f_robust + f_gauss)
    assert _judge(False, 1, seed=4, judge_robust_cost=True, judge_max_f=between)[0] == 1
    assert _judge(False, 0, seed=4, judge_robust_cost=True, judge_max_f=between)[0] == 0
    assert _judge(False, 1, seed=4, judge_robust_cost=False, judge_max_f=between)[0] == 0
    # three right pairs and a wrong one: rejected though its robust F is within the limit
    _, entry = _judge(True, 1, seed=4, judge_max_f=np.inf)
    assert entry["consistent_pairs"] == 3 and entry["pairs"] == 4
    assert entry["f_statistic_robust"] < entry["f_statistic"]
    between = 0.5 * (entry["f_statistic_robust"] + entry["f_statistic"])
    assert _judge(True, 1, seed=4, judge_max_f=between)[0] == 0


def test_closure_judged_alone_must_pass_the_f_test_in_both_costs():
    """``judge_alone_both_costs``: a closure that no recent hypothesis agrees with is accepted
    only when its F statistic is within ``judge_max_f`` in χ² and in the solver's robust cost;
    one that another hypothesis agrees with needs only one of them.

    The loop of seed 5 has the robust F of its three right pairs above the Gaussian one (over
    seeds 1-8 two loops do), so a limit between the two separates the rules."""
    _, entry = _judge(False, seed=5, judge_max_f=np.inf)
    f_gauss, f_robust = entry["f_statistic"], entry["f_statistic_robust"]
    assert entry["consistent_pairs"] == entry["pairs"] == 3
    assert 0.0 < f_gauss < f_robust  # the premise: the robust cost grew more
    between = 0.5 * (f_gauss + f_robust)
    alone, entry = _judge(False, 0, seed=5, judge_max_f=between)
    assert alone == 0 and entry["agreeing_hypotheses"] == 0
    assert _judge(False, 1, seed=5, judge_max_f=between)[0] == 1
    assert _judge(False, 0, seed=5, judge_max_f=between, judge_alone_both_costs=False)[0] == 1
    # below both: rejected either way; above both: accepted alone too
    assert _judge(False, 0, seed=5, judge_max_f=0.5 * f_gauss)[0] == 0
    assert _judge(False, 0, seed=5, judge_max_f=2.0 * f_robust)[0] == 1


def test_closure_that_lowers_the_loops_chi2_must_pass_the_f_test_in_the_robust_cost(monkeypatch):
    """``judge_negative_f_robust``: a closure whose merge lowers the loop's χ² (a negative F
    statistic) is accepted only when its F statistic in the solver's robust cost is within
    ``judge_max_f``, even when a recent hypothesis agrees with it.

    The three right pairs are judged with the loop's cost after the merge read as 1 % below
    the cost before in χ² and ``rise`` above it in the robust cost; with ``rise`` 0 the
    closure passes either way."""
    import slam.line_slam.loop_closer as lc

    real = lc.residual_chi2

    def judged(rise, **settings):
        calls = []

        def fake(g, loop_from, *kernel):
            plain, robust, line = real(g, loop_from, *kernel)
            calls.append((plain, robust))
            if len(calls) == 2:  # after the merge: χ² down, the robust cost up by `rise`
                (p0, r0) = calls[0]
                return 0.99 * p0, r0 * (1.0 + rise), line
            return plain, robust, line

        def patch():
            monkeypatch.setattr(lc, "residual_chi2", fake)

        try:
            return _judge(False, 1, judge_max_f=10.0, before_judging=patch, **settings)
        finally:
            monkeypatch.setattr(lc, "residual_chi2", real)

    assert RunConfig().slam.loop_closure.judge_negative_f_robust  # the default
    accepted, entry = judged(0.0)
    assert accepted == 1 and entry["f_statistic"] < 0.0
    accepted, entry = judged(1.0)
    assert entry["f_statistic"] < 0.0 < 10.0 < entry["f_statistic_robust"]
    assert entry["consistent_pairs"] == entry["pairs"] == 3 and entry["agreeing_hypotheses"] == 1
    assert accepted == 0
    assert judged(1.0, judge_negative_f_robust=False)[0] == 1


def test_judge_from_converged_compares_the_closure_with_the_loop_at_its_own_optimum():
    """``judge_from_converged``: the loop without the closure is solved first, so a start away
    from the loop's optimum does not count for the closure.  With the trajectory's second half
    bent 0.3 m before judging, the F statistic of the three right pairs falls far below the
    unbent one (the solve that merges them also undoes the bend); solved first, it is the
    unbent one's."""
    inf = {"judge_max_f": np.inf}
    f_ref = _judge(False, judge_from_converged=True, **inf)[1]["f_statistic"]
    f_unbent = _judge(False, judge_from_converged=False, **inf)[1]["f_statistic"]
    f_bent = _judge(False, bend_m=0.3, judge_from_converged=False, **inf)[1]["f_statistic"]
    f_bent_solved = _judge(False, bend_m=0.3, judge_from_converged=True, **inf)[1]["f_statistic"]
    assert RunConfig().slam.loop_closure.judge_from_converged  # the default
    assert f_ref > 0.0
    assert f_unbent == pytest.approx(f_ref, rel=0.05)  # the fixture's loop is converged
    assert f_bent < 0.0  # the premise: the bend's relief outweighs the closure's cost
    assert f_bent_solved == pytest.approx(f_ref, rel=0.05)


def test_judge_cost_counts_an_outlier_line_as_the_solver_does(loop_runs):
    """The judge's loop cost in the solver's kernel (``judge_robust_cost``): each line factor
    adds ``2ρ(‖e‖)`` (Cauchy: ``k² log(1 + χ²/k²)``), the odometry its χ².  One line moved
    2 m off raises the Gaussian total by thousands, the Cauchy total by at most
    ``k² log(1 + χ²/k²)`` of that factor."""
    from slam.line_slam.audit import residual_chi2

    g = loop_runs[3]["isam2"][0].graph
    k = 3.0
    plain, plain_r, line = residual_chi2(g, 10)
    assert plain_r == pytest.approx(plain, rel=1e-12)  # no kernel: the χ² total
    plain_c, robust, line_r = residual_chi2(g, 10, "cauchy", k)
    assert plain_c == plain
    np.testing.assert_array_equal(line, line_r)
    odo = plain - line.sum()
    assert odo > 0.0
    np.testing.assert_allclose(robust, odo + np.sum(k**2 * np.log1p(line / k**2)), rtol=1e-12)
    assert robust < plain
    # one observation of the loop's last pose moved 2 m along its normal
    f = int(np.flatnonzero(g.factor_pose == g.n_poses - 1)[0])
    z = g.factor_z[f].copy()
    g.factor_z[f, 0] += 2.0
    try:
        plain_off, robust_off, line_off = residual_chi2(g, 10, "cauchy", k)
    finally:
        g.factor_z[f] = z
    pos = int(np.searchsorted(np.flatnonzero(g.factor_pose >= 10), f))
    grown = float(line_off[pos] - line[pos])
    assert plain_off - plain > 1000.0 and grown > 1000.0
    assert 0.0 < robust_off - robust <= k**2 * np.log1p(grown / k**2) + 1e-9


def test_estimated_model_error_finds_the_line_worlds_exact_lines():
    """The line world's lines carry their exact covariances: started from the default model error
    (2 cm, 0.01 rad), the estimate (the default) falls to a fraction of it and the factors are
    re-weighted."""
    world = corridor_loop(length=10.0, width=6.0, piece=3.0, door=1.0)
    path = loop_path(10, 6, 0.5, laps=1.0)
    run = simulate_run(world, path, seed=201, motion=MOTION)
    assert SlamConfig().line_model_error == "estimated"
    _, res, _ = run_slam(run, SlamConfig(motion=MOTION))
    est = res.stats["line_model_error"]
    assert est["updates"] >= 1 and est["samples"] >= 50
    assert est["sigma_offset_m"] < 0.005 and est["sigma_angle_rad"] < 0.003
    _, fixed, _ = run_slam(run, SlamConfig(motion=MOTION, line_model_error="fixed"))
    assert "line_model_error" not in fixed.stats
    # re-weighted with the smaller model error, the poses are more certain than with the default
    assert np.median(res.pose_covariances[:, 2, 2]) < np.median(fixed.pose_covariances[:, 2, 2])


def test_a_hypothesis_contradicting_a_recent_closure_is_turned_away():
    """``consistent_with_accepted``: along a straight corridor, a closure accepted at keyframe
    30 ties it to keyframe 5.  A hypothesis at keyframe 35 onto keyframe 6 that moves the
    robot 25 cm across the corridor (a parallel wall matched) contradicts it beyond χ²'s
    quantile; 2 cm across, or metres along the corridor (not measured there), does not; nor
    does anything once the accepted closure is ``local_keyframes`` old."""
    from slam.frontend.loop_closure import LoopLines, correction_covariance
    from slam.geometry import pose_compose
    from slam.line_slam.clock import StageClock
    from slam.line_slam.drift import DriftAccumulator
    from slam.line_slam.loop_closer import Hypothesis, LoopCloser, _Accepted

    config = SlamConfig()
    lcc = config.loop_closure
    drift = DriftAccumulator()
    for k in range(60):  # 0.2 m steps along x, 1 cm and 1 mrad of drift each
        drift.add_step(np.diag([1e-4, 1e-4, 1e-6]), 0.2 * k, np.array([0.2, 0.0, 0.0]))
    closer = LoopCloser(None, None, drift, None, None, config, {}, StageClock())  # type: ignore[arg-type]
    walls = LoopLines(
        np.array([np.pi / 2, -np.pi / 2, np.pi / 2]),
        np.array([1.0, 1.0, 1.4]),
        np.array([[[-3.0, y], [3.0, y]] for y in (1.0, -1.0, 1.4)]),
    )
    cov = correction_covariance(
        walls, walls, [(0, 0), (1, 1), (2, 2)], np.zeros(2), np.zeros(3), lcc, (1.0, 0.1)
    )
    normal = np.array([0.0, 1.0])  # keyframe frames are the world's here (heading 0)
    closer._accepted.append(
        _Accepted(Hypothesis(30, 5, drift.relative(5, 30), normal, cov), 0.0, [])
    )

    def hypothesis(keyframe: int, old: int, offset: tuple[float, float]) -> Hypothesis:
        z = pose_compose(drift.relative(old, keyframe), np.array([*offset, 0.0]))
        return Hypothesis(keyframe, old, z, normal, cov)

    reason = closer.contradiction(hypothesis(35, 6, (0.0, 0.25)))
    assert reason is not None and "keyframe 30" in reason and "2 dof" in reason
    assert closer.contradiction(hypothesis(35, 6, (0.0, 0.02))) is None
    assert closer.contradiction(hypothesis(35, 6, (2.0, 0.0))) is None
    assert closer.contradiction(hypothesis(30 + lcc.local_keyframes, 6, (0.0, 0.25))) is None


def test_graph_test_is_the_mahalanobis_distance_of_the_relative_pose():
    """``graph_test``: the hypothesis' relative pose against the graph's, under the covariance
    the two poses' joint marginal gives that relative pose (its Jacobian checked against
    numerical derivatives of the relative pose under right perturbations); the scale
    multiplies the graph's part, the hypothesis' own covariance adds to it."""
    from types import SimpleNamespace

    from slam.frontend.loop_closure import LoopClosure
    from slam.geometry import pose_compose, pose_exp
    from slam.graph.problem import LineGraph
    from slam.line_slam.clock import StageClock
    from slam.line_slam.loop_closer import Hypothesis, LoopCloser

    g = LineGraph()
    x_old, x_k = np.array([1.0, 2.0, 0.4]), np.array([4.0, 0.5, 2.1])
    g.add_pose(x_old)
    g.add_pose(x_k)
    rng = np.random.default_rng(5)
    A = rng.normal(size=(6, 6)) * 0.03
    P = A @ A.T + np.diag([1e-4, 1e-4, 1e-6, 1e-4, 1e-4, 1e-6])
    backend = SimpleNamespace(joint_pose_covariance=lambda graph, poses: P)
    closer = LoopCloser(
        SimpleNamespace(graph=g),  # type: ignore[arg-type]
        None,  # type: ignore[arg-type]
        None,  # type: ignore[arg-type]
        None,  # type: ignore[arg-type]
        backend,  # type: ignore[arg-type]
        SlamConfig(),
        {},
        StageClock(),
    )
    found = LoopClosure(np.array([0.06, -0.04, 0.015]), [(0, 0), (1, 1)], 10.0, 1.0)
    C = np.diag([0.02, 0.02, 0.005]) ** 2
    h = Hypothesis(1, 0, np.zeros(3), None, C)
    first = closer.graph_test(found, np.arange(2), 1, 0, h)
    assert first is not None and first.dof == 3
    assert first.chi2 is None and first.scale is None  # no closure accepted yet: no scale
    est = pose_between(x_old, x_k)
    e = pose_log(pose_between(est, closer.hypothesis(found, np.arange(2), 1, 0).z))
    assert np.linalg.norm(e) > 0.05

    def relative(xi: np.ndarray) -> np.ndarray:
        a = pose_compose(x_old, pose_exp(xi[:3]))
        b = pose_compose(x_k, pose_exp(xi[3:]))
        return pose_log(pose_between(est, pose_between(a, b)))

    J = np.zeros((3, 6))
    for i in range(6):
        d = np.zeros(6)
        d[i] = 1e-6
        J[:, i] = (relative(d) - relative(-d)) / 2e-6
    S = J @ P @ J.T
    assert first.raw == pytest.approx(float(e @ np.linalg.solve(S, e)), rel=1e-5)
    # with a scale the graph's part grows, the hypothesis' own covariance adds
    closer._graph_tests = [_graph_test_of(np.full(3, 0.02), np.eye(3) * 1e-4, np.eye(3) * 1e-12)]
    k = closer.graph_scale()
    assert k is not None and k > 100
    scaled = closer.graph_test(found, np.arange(2), 1, 0, h)
    assert scaled is not None and scaled.scale == k
    assert scaled.chi2 == pytest.approx(float(e @ np.linalg.solve(k * S + C, e)), rel=1e-5)
    assert scaled.chi2 < scaled.raw / k
    # its terms give the same χ² at any scale (what it adds to the scale once accepted)
    for k_any in (1.0, k, 10 * k):
        assert scaled.chi2_at(k_any) == pytest.approx(
            float(e @ np.linalg.solve(k_any * S + C, e)), rel=1e-5
        )
    # graph_window: window_sigmas standard deviations of the scaled covariance, at least the
    # minimum windows
    lcc = closer.config.loop_closure
    window = closer.graph_window(0, 1)
    assert window is not None
    expected_xy = lcc.window_sigmas * np.sqrt(np.max(np.linalg.eigvalsh(k * S[:2, :2])))
    expected_th = lcc.window_sigmas * np.sqrt(k * S[2, 2])
    assert window[0] == pytest.approx(max(expected_xy, lcc.min_window_xy_m), rel=1e-5)
    assert window[1] == pytest.approx(max(expected_th, lcc.min_window_theta_rad), rel=1e-5)
    closer._graph_tests, closer._graph_scale = [], None
    assert closer.graph_window(0, 1) is None  # no closure yet: the drift's window alone


def _graph_test_of(e, S, C):
    from slam.line_slam.loop_closer import GraphTest, scaled_chi2_terms

    w2, lam = scaled_chi2_terms(e, S, C)
    return GraphTest(float(e @ np.linalg.solve(S, e)), e.shape[0], None, None, w2, lam)


def test_a_closures_chi2_at_every_scale_from_its_terms(rng):
    """``Σ w² / (k λ + 1)`` is ``eᵀ (k S + C)⁻¹ e`` for any scale ``k`` (S and C diagonalised
    together), including ``k = 0`` (``C`` alone) and a singular ``S``."""
    from slam.line_slam.loop_closer import scaled_chi2_terms

    for d in (2, 3):
        for _ in range(20):
            a, b = rng.normal(size=(d, d)), rng.normal(size=(d, d))
            S, C = a @ a.T * rng.uniform(1e-6, 1e2), b @ b.T + 1e-3 * np.eye(d)
            e = rng.normal(size=d)
            w2, lam = scaled_chi2_terms(e, S, C)
            for k in (0.0, 1.0, 37.5, 1e4):
                direct = e @ np.linalg.solve(k * S + C, e)
                assert np.sum(w2 / (k * lam + 1.0)) == pytest.approx(direct, rel=1e-8)
    v = np.array([1.0, 2.0, 0.0])
    S = np.outer(v, v)  # rank one
    e = np.array([0.3, -0.1, 0.2])
    w2, lam = scaled_chi2_terms(e, S, np.eye(3))
    assert np.sum(w2 / (5.0 * lam + 1.0)) == pytest.approx(
        e @ np.linalg.solve(5 * S + np.eye(3), e)
    )


def test_the_likelihood_bound_of_the_scale(rng):
    """The one-sided likelihood-ratio upper bound of ``k ≥ 1`` in ``e ~ N(0, k S + C)``: at
    it the negative log-likelihood has risen from its minimum by the deviance over 2; with
    many closures drawn from ``k₀ S + C``, just above ``k₀``; a closure whose error its own
    covariance explains, with ``S`` far smaller than ``C``, says little about ``k``: a bound
    that lets ``k S`` grow to ``C``'s size; never below 1."""
    from slam.line_slam.loop_closer import _scale_upper_bound, scaled_chi2_terms

    deviance = 9.55
    S = np.diag([1e-4, 1e-4, 1e-6])

    def nll(w2, lam, k):
        return 0.5 * float(np.sum(np.log1p(k * lam) + w2 / (1.0 + k * lam)))

    w2, lam = scaled_chi2_terms(np.sqrt(np.diag(S)) * 10.0, S, 1e-12 * np.eye(3))
    k = _scale_upper_bound(w2, lam, deviance)  # k̂ = 100 (the mean χ² per dof)
    assert k > 1000
    assert nll(w2, lam, k) - nll(w2, lam, 100.0) == pytest.approx(deviance / 2, rel=1e-6)
    k0, C = 30.0, 10.0 * S
    L = np.linalg.cholesky(k0 * S + C)
    terms = [scaled_chi2_terms(L @ rng.normal(size=3), S, C) for _ in range(400)]
    w2, lam = (np.concatenate(t) for t in zip(*terms, strict=True))
    assert k0 < _scale_upper_bound(w2, lam, deviance) < 1.4 * k0
    C = np.diag([0.04, 0.04, 1e-4])  # 20 cm against the graph's 1 cm
    w2, lam = scaled_chi2_terms(np.array([0.02, 0.0, 0.0]), S, C)
    assert _scale_upper_bound(w2, lam, deviance) > 400
    w2, lam = scaled_chi2_terms(np.zeros(3), np.eye(3), np.eye(3))
    assert _scale_upper_bound(w2, lam, deviance) >= 1.0


def test_graph_scale_is_the_upper_confidence_bound_of_what_closures_measured(rng):
    """An upper bound of the factor ``k`` on the graph's covariance: the closures'
    ``Σ eᵀS⁻¹e`` over χ²'s quantile ``1 − p`` of their dof (all of their error put on the
    graph); with ``graph_scale_with_hypotheses`` the smaller of that and the likelihood bound
    with their own covariance; never below 1; None before any."""
    from scipy.stats import chi2

    from slam.line_slam.clock import StageClock
    from slam.line_slam.loop_closer import LoopCloser, _scale_upper_bound

    default = SlamConfig()
    lcc = replace(default.loop_closure, graph_scale_with_hypotheses=True)
    config = replace(default, loop_closure=lcc)
    p = config.loop_closure.consistency_probability
    closer = LoopCloser(None, None, None, None, None, config, {}, StageClock())  # type: ignore[arg-type]
    assert closer.graph_scale() is None
    assert closer.graph_report() == {
        "dof": 0,
        "chi2_per_dof": None,
        "chi2_per_dof_with_hypotheses": None,
        "scale": None,
    }

    def measured(tests):
        closer._graph_tests, closer._graph_scale = tests, None
        return closer.graph_scale()

    def likelihood_bound(tests):
        w2 = np.concatenate([t.w2 for t in tests])
        lam = np.concatenate([t.lam for t in tests])
        return _scale_upper_bound(w2, lam, chi2.ppf(2 * p - 1, 1))

    S = np.diag([1e-4, 1e-4, 1e-6])
    e = np.sqrt(np.diag(S)) * 10.0  # 100 per dof under S
    for C in (1e-12 * np.eye(3), np.diag([0.04, 0.04, 1e-4])):
        for n in (1, 100):
            tests = [_graph_test_of(e, S, C)] * n
            alone = 100.0 * 3 * n / chi2.ppf(1 - p, 3 * n)
            k = measured(tests)
            assert k == pytest.approx(min(alone, likelihood_bound(tests)), rel=1e-9)
            report = closer.graph_report()
            assert report["dof"] == 3 * n and report["chi2_per_dof"] == pytest.approx(100.0)
    # many closures 100 per dof under S alone: close to 100 either way
    assert 100 < measured([_graph_test_of(e, S, 1e-12 * np.eye(3))] * 100) < 135
    # the same errors within hypotheses 20 cm wide: the likelihood bound is the smaller
    C = np.diag([0.04, 0.04, 1e-4])
    wide = [_graph_test_of(e, S, C)] * 100
    assert measured(wide) < 100
    closer.config = default  # by default the first bound alone
    assert measured(wide) == pytest.approx(100.0 * 300 / chi2.ppf(1 - p, 300))
    closer.config = config
    measured(wide)
    with_c = float(e @ np.linalg.solve(S + C, e)) / 3
    assert closer.graph_report()["chi2_per_dof_with_hypotheses"] == pytest.approx(with_c)
    # closures as the graph's covariance says: a bound of a few; far inside it: 1
    assert 1.0 < measured([_graph_test_of(0.1 * e, S, 1e-12 * np.eye(3))] * 10) < 3.0
    assert measured([_graph_test_of(0.01 * e, S, 1e-12 * np.eye(3))] * 10) == 1.0


def test_the_graph_gate_on_a_simulated_loop(loop_runs):
    """Where the estimator is told the true noise, the accepted closures find the graph's
    covariance of the loop about right (not over-confident: their χ² per dof within χ²'s
    quantile), and a hypothesis that moves the robot a metre from where the graph has it
    is turned away before the judge; one a centimetre off is not."""
    from scipy.stats import chi2

    from slam.frontend.loop_closure import LoopClosure

    slam = loop_runs[3]["isam2"][0]
    closer = slam.loop_closer
    report = closer.graph_report()
    p = slam.config.loop_closure.consistency_probability
    assert report["dof"] >= 6
    assert report["chi2_per_dof"] < chi2.ppf(p, report["dof"]) / report["dof"]
    assert report["scale"] is not None and report["scale"] >= 1.0
    g = slam.graph
    pose = g.n_poses - 1
    k_old = pose // 3
    C = np.diag([0.02, 0.02, 0.005]) ** 2
    h = _hypothesis_with_cov(pose, k_old, C)
    old = np.flatnonzero(g.landmark_alive)[:2]
    far = closer.graph_test(
        LoopClosure(np.array([1.0, 0.0, 0.0]), [(0, 0), (1, 1)], 10.0, 1.0), old, pose, k_old, h
    )
    near = closer.graph_test(
        LoopClosure(np.array([0.01, 0.0, 0.0]), [(0, 0), (1, 1)], 10.0, 1.0), old, pose, k_old, h
    )
    assert far is not None and far.chi2 is not None and far.chi2 > chi2.ppf(p, far.dof)
    assert near is not None and near.chi2 is not None and near.chi2 < chi2.ppf(p, near.dof)
    # turned away by apply: logged as gated, counted, nothing solved, nothing merged
    state = (g.poses.copy(), len(g.merge_log))
    gated = slam.counters["loop_closures_gated"]
    undone = slam.counters["loop_closures_undone"]
    candidates = slam.counters["loop_closure_candidates"]
    wrong = LoopClosure(np.array([1.0, 0.0, 0.0]), [(0, 0), (1, 1)], 10.0, 1.0)
    local = np.flatnonzero(g.landmark_alive)[-2:]
    assert closer.apply(local, old, wrong, pose, 1.0, 0, h) == 0
    last = closer.attempts[-1]
    assert last.kind == "gated" and "inconsistent with the graph" in (last.reason or "")
    assert last.graph_chi2 is not None and last.graph_chi2 > chi2.ppf(p, 3)
    assert slam.counters["loop_closures_gated"] == gated + 1
    assert slam.counters["loop_closures_undone"] == undone
    assert slam.counters["loop_closure_candidates"] == candidates  # not judged
    np.testing.assert_array_equal(g.poses, state[0])
    assert len(g.merge_log) == state[1]


def _hypothesis_with_cov(pose, k_old, cov):
    from slam.line_slam.loop_closer import Hypothesis

    return Hypothesis(int(pose), int(k_old), np.zeros(3), None, cov)
