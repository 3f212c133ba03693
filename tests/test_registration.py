"""Line-to-line registration: exact recovery, Monte-Carlo consistency, degenerate corridors."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from slam.errors import ConfigError, InputError
from slam.frontend import RegistrationConfig, register_lines
from slam.geometry import line_to_child, pose_between, pose_log, pose_retract
from slam.lines.lineset import LineSet

# A room: (r, α) of world walls and their visible extent along the tangent.
ROOM = [
    (4.0, 0.0, -3.0, 3.0),
    (3.0, np.pi / 2, -4.0, 4.0),
    (4.0, np.pi, -3.0, 3.0),
    (3.0, -np.pi / 2, -4.0, 4.0),
    (1.5, 0.6, -0.5, 0.8),
]


def world_lines(walls) -> tuple[np.ndarray, np.ndarray]:
    ra = np.array([(r, a) for r, a, _, _ in walls])
    n = np.stack([np.cos(ra[:, 1]), np.sin(ra[:, 1])], -1)
    t = np.stack([-np.sin(ra[:, 1]), np.cos(ra[:, 1])], -1)
    s = np.array([(s0, s1) for _, _, s0, s1 in walls])
    ends = ra[:, :1, None] * n[:, None, :] + s[:, :, None] * t[:, None, :]
    return ra, ends


def observe(walls, pose, R_meas, rng=None):
    """Scan lines (sensor frame) seen from ``pose``, optionally with noise drawn from R_meas."""
    ra, ends = world_lines(walls)
    lines3 = np.column_stack([ra, np.zeros(len(ra))])
    z = line_to_child(lines3, pose)[0][:, :2]
    if rng is not None:
        z = z + np.stack([rng.multivariate_normal(np.zeros(2), R) for R in R_meas])
    c, s = np.cos(pose[2]), np.sin(pose[2])
    rot = np.array([[c, -s], [s, c]])
    ends_s = (ends - pose[:2]) @ rot  # world -> sensor
    return LineSet(z, np.asarray(R_meas), ends_s, np.arange(len(ra)))


def make_map(walls, P_map, rng=None):
    ra, ends = world_lines(walls)
    if rng is not None:
        ra = ra + np.stack([rng.multivariate_normal(np.zeros(2), P) for P in P_map])
    return LineSet(ra, np.asarray(P_map), ends, np.arange(len(ra)))


def covs(k, sr, sa, rho=0.3):
    c = rho * sr * sa
    return np.tile(np.array([[sr**2, c], [c, sa**2]]), (k, 1, 1))


def test_exact_recovery_from_a_poor_guess():
    true = np.array([0.7, -0.4, 0.3])
    # exact lines with tiny covariances: the prior's pull is negligible
    R = covs(len(ROOM), 1e-5, 1e-5)
    scan = observe(ROOM, true, R)
    mp = make_map(ROOM, covs(len(ROOM), 1e-5, 1e-5, 0.0))
    prior = pose_retract(true, np.array([0.25, -0.2, 0.08]))
    res = register_lines(scan, mp, prior, np.diag([0.3, 0.3, 0.1]) ** 2)
    assert res.matched and res.n_matches == len(ROOM)
    np.testing.assert_array_equal(res.matches, np.arange(len(ROOM)))
    np.testing.assert_allclose(res.pose_world_laser, true, atol=1e-6)


def test_monte_carlo_nees_is_consistent():
    rng = np.random.default_rng(7)
    true = np.array([0.5, 0.2, -0.4])
    R = covs(len(ROOM), 0.01, 0.004)
    P_map = covs(len(ROOM), 0.005, 0.002, 0.1)
    P_prior = np.diag([0.05, 0.05, 0.02]) ** 2
    cfg = RegistrationConfig(robust_kernel="none")
    nees = []
    for _ in range(400):
        scan = observe(ROOM, true, R, rng)
        mp = make_map(ROOM, P_map, rng)
        prior = pose_retract(true, rng.multivariate_normal(np.zeros(3), P_prior))
        res = register_lines(scan, mp, prior, P_prior, cfg)
        err = pose_log(pose_between(true, res.pose_world_laser))
        nees.append(err @ np.linalg.solve(res.cov, err))
    n = len(nees)
    lo, hi = chi2.ppf([0.005, 0.995], 3 * n) / n
    assert lo < np.mean(nees) < hi, np.mean(nees)


def test_corridor_keeps_the_prior_along_the_walls():
    corridor = [(1.0, np.pi / 2, -10.0, 10.0), (1.0, -np.pi / 2, -10.0, 10.0)]
    true = np.array([2.0, 0.1, 0.05])
    R = covs(2, 0.005, 0.002)
    scan = observe(corridor, true, R)
    mp = make_map(corridor, covs(2, 1e-4, 1e-4, 0.0))
    P_prior = np.diag([0.2, 0.05, 0.02]) ** 2
    prior = np.array([2.3, 0.12, 0.06])  # 0.3 m off along the corridor (x)
    res = register_lines(scan, mp, prior, P_prior)
    assert res.matched
    # lines fix y and θ; x stays where the prior put it (the laser frame is nearly aligned)
    assert abs(res.pose_world_laser[1] - true[1]) < 1e-3
    assert abs(res.pose_world_laser[2] - true[2]) < 1e-3
    assert abs(res.pose_world_laser[0] - 2.3) < 0.02
    eig = np.linalg.eigvalsh(res.information_lines)
    assert eig[0] < 1e-6 * eig[-1]  # one unobservable direction
    assert res.cov[0, 0] == pytest.approx(P_prior[0, 0], rel=0.05)


def test_parallel_walls_a_recess_apart_are_not_confused():
    walls = [(2.0, 0.0, -1.0, 1.0), (2.3, 0.0, -1.0, 1.0), (3.0, np.pi / 2, -3, 3)]
    true = np.array([0.0, 0.0, 0.0])
    seen = [walls[1], walls[2]]
    scan = observe(seen, true, covs(2, 1e-5, 1e-5))
    mp = make_map(walls, covs(3, 1e-5, 1e-5, 0.0))
    res = register_lines(scan, mp, np.array([0.05, 0.0, 0.0]), np.diag([0.05, 0.05, 0.02]) ** 2)
    np.testing.assert_array_equal(res.matches, [1, 2])
    np.testing.assert_allclose(res.pose_world_laser, true, atol=1e-6)


def test_far_collinear_wall_is_not_matched_without_overlap():
    walls = [(2.0, 0.0, 20.0, 25.0), (3.0, np.pi / 2, -3, 3), (3.0, -np.pi / 2, -3, 3)]
    scan_walls = [(2.0, 0.0, -1.0, 1.0), (3.0, np.pi / 2, -3, 3)]
    scan = observe(scan_walls, np.zeros(3), covs(2, 0.005, 0.002))
    mp = make_map(walls, covs(3, 1e-4, 1e-4, 0.0))
    res = register_lines(scan, mp, np.zeros(3), np.diag([0.05, 0.05, 0.02]) ** 2)
    assert res.matches[0] == -1 and res.matches[1] == 1


def test_no_lines_returns_the_prior():
    prior = np.array([1.0, 2.0, 0.3])
    P = np.eye(3) * 0.01
    res = register_lines(LineSet.empty(), make_map(ROOM, covs(5, 0.01, 0.01)), prior, P)
    assert not res.matched and res.n_matches == 0
    np.testing.assert_array_equal(res.pose_world_laser, prior)
    np.testing.assert_array_equal(res.cov, P)


def test_bad_inputs_raise_lineslam_errors():
    scan = observe(ROOM, np.zeros(3), covs(5, 0.01, 0.01))
    mp = make_map(ROOM, covs(5, 0.01, 0.01))
    with pytest.raises(InputError, match="positive definite"):
        register_lines(scan, mp, np.zeros(3), np.zeros((3, 3)))
    with pytest.raises(InputError, match="not finite"):
        register_lines(scan, mp, np.array([np.nan, 0, 0]), np.eye(3))
    with pytest.raises(InputError, match="shapes"):
        LineSet(np.zeros((2, 2)), np.zeros((3, 2, 2)), np.zeros((2, 2, 2)), np.zeros(2, int))
    with pytest.raises(ConfigError):
        RegistrationConfig(gate_probability=1.5)
