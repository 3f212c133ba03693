"""End to end on the project's simulator: ray-cast scans → linefit → LineSlam (iSAM2)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from slam.geometry import pose_between, pose_log
from slam.line_slam import LineSlam, SlamConfig, SlamWarning
from slam.models import MotionNoiseConfig
from slam.sim import OdometryNoiseConfig, SimConfig, get_world
from slam.sim.simulate import simulate

ODOMETRY = OdometryNoiseConfig(sigma_trans_per_m=0.02, sigma_rot_per_rad=0.02, sigma_rot_per_m=0.02)


def matching_motion_model(odo: OdometryNoiseConfig) -> MotionNoiseConfig:
    """The simulator's odometry noise in the graph's motion model (tiny floors)."""
    return MotionNoiseConfig(
        sigma_xy_per_m=odo.sigma_trans_per_m,
        sigma_xy_per_rad=0.0,
        sigma_theta_per_m=odo.sigma_rot_per_m,
        sigma_theta_per_rad=odo.sigma_rot_per_rad,
        sigma_xy_min_m=1e-4,
        sigma_theta_min_rad=1e-5,
    )


EXACT_LINES = {"line_model_sigma_r_m": 0.0, "line_model_sigma_alpha_rad": 0.0}
"""The simulator's lines have no model error (straight walls, the fit's noise model is the
simulator's): like the motion model above, the estimator is given the true noise model."""


def relations(poses: np.ndarray, truth: np.ndarray, gap: int) -> float:
    est = pose_between(poses[:-gap], poses[gap:])
    ref = pose_between(truth[:-gap], truth[gap:])
    d = pose_between(ref, est)
    return float(np.hypot(d[:, 0], d[:, 1]).mean())


@pytest.fixture(scope="module")
def loop_result():
    log = simulate(get_world("loop"), None, SimConfig(odometry=ODOMETRY), seed=0)
    slam = LineSlam(SlamConfig(motion=matching_motion_model(ODOMETRY), **EXACT_LINES))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SlamWarning)
        for scan in log.scans():
            slam.add_scan(scan)  # extracts the lines itself
        slam.optimize()
    return log, slam.result()


def test_loop_far_below_odometry(loop_result):
    log, res = loop_result
    truth = log.poses_world_laser
    odo = log.poses_odom_laser
    e = pose_log(pose_between(truth, res.poses_world_laser))
    e_odo = pose_log(pose_between(truth, odo))
    ate = np.sqrt(np.mean(np.sum(e[:, :2] ** 2, axis=1)))
    ate_odo = np.sqrt(np.mean(np.sum(e_odo[:, :2] ** 2, axis=1)))
    assert ate_odo > 1.0 and ate < 0.02  # metres of drift → centimetres
    for gap in (3, 30, 100):  # ≈ 1 m, 9 m, 30 m of path
        rel, rel_odo = relations(res.poses_world_laser, truth, gap), relations(odo, truth, gap)
        assert rel < 0.05 and rel < 0.1 * rel_odo
    assert relations(odo, truth, 30) > 0.1  # "odometry tens of cm"
    nees = np.einsum("ni,nij,nj->n", e, np.linalg.inv(res.pose_covariances), e)
    assert 1.0 < nees.mean() < 6.0  # one run, correlated poses: a sanity band (MC elsewhere)


def test_map_lines_lie_on_the_simulated_walls(loop_result):
    """Map lines are statistically the lines of true wall segments: the normalised error
    ``d²`` of each against its wall (own covariance) averages about 2 (χ²₂) with few beyond the
    99.9 % gate, none is grossly off, and every visible piece lies within the extent of the
    wall segments on its line (± 0.3 m).  Pieces may bridge doors and recesses that the
    extraction does not resolve at grazing angles."""
    log, res = loop_result
    segs = log.world.segments
    d = segs[:, 1] - segs[:, 0]
    length = np.linalg.norm(d, axis=1)
    t = d / length[:, None]
    nrm = np.column_stack([t[:, 1], -t[:, 0]])
    r_w = np.sum(nrm * segs[:, 0], axis=1)
    a_w = np.arctan2(nrm[:, 1], nrm[:, 0])
    d2_all = []
    for la, P, pieces in zip(
        res.landmarks_r_alpha, res.landmark_covariances, res.landmark_segments, strict=True
    ):
        # the wall line in the map line's representative
        flip = np.cos(a_w - la[1]) < 0
        r_t = np.where(flip, -r_w, r_w)
        a_t = np.where(flip, a_w + np.pi, a_w)
        e = np.column_stack([la[0] - r_t, np.angle(np.exp(1j * (la[1] - a_t)))])
        d2 = np.einsum("wi,ij,wj->w", e, np.linalg.inv(P), e)
        d2_all.append(d2.min())
        w = np.flatnonzero(d2 < 40.0)
        assert w.size, (la, d2.min())
        ref = w[0]
        ends = np.einsum("wpd,d->wp", segs[w] - segs[ref, 0], t[ref])
        for piece in pieces:
            s_piece = (piece - segs[ref, 0]) @ t[ref]
            assert s_piece.min() > ends.min() - 0.3 and s_piece.max() < ends.max() + 0.3
    d2_all = np.array(d2_all)
    assert np.mean(d2_all) < 2.0 * 1.5 and np.mean(d2_all > 13.8) <= 0.05
    # the long walls are mapped once each, not as piles of duplicates
    lengths = np.array(
        [np.linalg.norm(p[:, 1] - p[:, 0], axis=1).sum() for p in res.landmark_segments]
    )
    assert np.sum(lengths > 10.0) >= 6
    long_lines = res.landmarks_r_alpha[lengths > 10.0]
    for i in range(len(long_lines)):
        for j in range(i + 1, len(long_lines)):
            same = (
                abs(long_lines[i, 0] - long_lines[j, 0]) < 0.1
                and abs(np.angle(np.exp(1j * (long_lines[i, 1] - long_lines[j, 1])))) < 0.02
            )
            assert not same


def test_pose_nees_over_seeded_simulator_runs():
    """Lean Monte Carlo on the simulator (3 seeds, the first 100 scans of the loop): the pose
    NEES at three spaced scans, averaged over the 9 samples, lies in the 99 % band of an
    average of 9 χ²₃ (a longer study: scripts/study_graph_nees.py)."""
    from scipy.stats import chi2

    world = get_world("loop")
    nees = []
    for seed in range(1, 4):
        log = simulate(world, None, SimConfig(odometry=ODOMETRY), seed=seed)
        slam = LineSlam(SlamConfig(motion=matching_motion_model(ODOMETRY), **EXACT_LINES))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", SlamWarning)
            for k, scan in enumerate(log.scans()):
                if k == 100:
                    break
                slam.add_scan(scan)
            slam.optimize()
        res = slam.result()
        e = pose_log(pose_between(log.poses_world_laser[:100], res.poses_world_laser))
        n = np.einsum("ni,nij,nj->n", e, np.linalg.inv(res.pose_covariances), e)
        nees.extend(n[[33, 66, 99]])
    lo, hi = chi2.ppf([0.005, 0.995], 3 * len(nees)) / len(nees)
    assert lo < np.mean(nees) < hi
