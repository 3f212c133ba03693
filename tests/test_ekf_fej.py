"""The FEJ-EKF and the OC-EKF (``EkfConfig.jacobians``: first-estimates,
observability-constrained).

The nonlinear line-SLAM model cannot tell where the world is: moving or turning the robot and
every landmark together changes no measurement, three unobservable directions.  The standard
EKF linearises at estimates that change from one step to the next, and its linearised model
observes them (with line landmarks all three: a translation moves ``r`` by ``cos α``,
``sin α`` of the current ``α`` estimates): the spurious information that makes it
over-confident over long runs (Huang, Mourikis & Roumeliotis 2008, 2010).  The FEJ-EKF
linearises at the first estimates and keeps all three; the OC-EKF projects the current
Jacobians onto the closest ones that keep them.  Checked on the observability matrix
of the filter's own ``F`` and ``H`` over a noisy run.
"""

from __future__ import annotations

import numpy as np
import pytest

from slam.ekf import EkfConfig, EkfSlam
from slam.ekf.update import line_measurements, observability_constrained, unobservable_directions
from slam.errors import ConfigError
from slam.geometry import pose_compose, predict_line_measurement

WALLS = np.array([[4.0, 0.1], [3.0, 1.7], [5.0, -1.4]])  # world (r, α), not parallel
SIGMA_R, SIGMA_A = 0.05, 0.02


def _measure(rng, pose, walls):
    z, _, _ = predict_line_measurement(walls, pose[None, :])
    return z + rng.normal(0.0, [SIGMA_R, SIGMA_A], size=z.shape)


def _run(jacobians: str, seed: int = 3, steps: int = 8):
    """A noisy run seeing the same three walls; the filter's F, H and its first estimates."""
    rng = np.random.default_rng(seed)
    cfg = EkfConfig(jacobians=jacobians, merge_landmarks=False, line_sigma_extra=(0.0, 0.0))
    ekf = EkfSlam(cfg)
    truth = np.array([0.0, 0.0, 0.0])
    ekf.initialize(truth)
    R = np.tile(np.diag([SIGMA_R**2, SIGMA_A**2]), (3, 1, 1))
    ends = np.zeros((3, 2, 2))
    ekf.add_landmarks(_measure(rng, truth, WALLS), R, ends)
    x0 = ekf.x.copy()  # the first estimates: pose, then landmarks
    Fs, Hs = [], []
    for _ in range(steps):
        u_true = np.array([0.4, 0.05, 0.12])
        truth = pose_compose(truth, u_true)
        u_meas = u_true + rng.normal(0.0, [0.03, 0.03, 0.02])
        ekf.predict(u_meas, np.diag([0.03**2, 0.03**2, 0.02**2]))
        Fs.append(ekf.F.copy())
        ekf.update(np.arange(3), _measure(rng, truth, WALLS), R)
        Hs.append(ekf.H.copy())
    return ekf, x0, Fs, Hs


def _observability(Fs, Hs, n):
    rows, Phi = [], np.eye(n)
    for F, H in zip(Fs, Hs, strict=True):
        step = np.eye(n)
        step[:3, :3] = F
        Phi = step @ Phi
        rows.append(H @ Phi)
    return np.vstack(rows)


def _unobservable_directions(x0):
    """Moving the world by (dx, dy) and turning it by dφ about the origin, at ``x0``."""
    n = x0.shape[0]
    N = np.zeros((n, 3))
    N[0, 0] = N[1, 1] = 1.0
    N[:3, 2] = [-x0[1], x0[0], 1.0]
    for j in range((n - 3) // 2):
        alpha = x0[4 + 2 * j]
        N[3 + 2 * j, :2] = [np.cos(alpha), np.sin(alpha)]
        N[4 + 2 * j, 2] = 1.0
    return N


def _nullity(M):
    s = np.linalg.svd(M, compute_uv=False)
    return int(np.sum(s < 1e-9 * s[0])) + max(M.shape[1] - M.shape[0], 0)


@pytest.mark.parametrize("jacobians", ["first-estimates", "observability-constrained"])
@pytest.mark.parametrize("seed", [3, 11])
def test_fej_and_oc_keep_three_unobservable_directions_the_standard_ekf_none(seed, jacobians):
    fej, x0, Fs, Hs = _run(jacobians, seed)
    M = _observability(Fs, Hs, x0.shape[0])
    assert M.shape == (2 * 3 * 8, 9)
    assert _nullity(M) == 3
    # and they are the world's translation and rotation at the first estimates
    N = _unobservable_directions(x0)
    assert np.linalg.norm(M @ N) < 1e-10 * np.linalg.norm(M)

    std, x0_std, Fs_std, Hs_std = _run("current", seed)
    np.testing.assert_array_equal(x0_std, x0)  # the same data up to the first update
    M_std = _observability(Fs_std, Hs_std, x0.shape[0])
    assert _nullity(M_std) == 0
    # each of the world's motions is "observed" (the spurious information)
    gain = np.linalg.norm(M_std @ _unobservable_directions(x0_std), axis=0)
    assert np.all(gain > 1e-4 * np.linalg.norm(M_std)), gain
    # the two filters differ only in their Jacobians: estimates close, not equal
    assert 0.0 < np.max(np.abs(fej.x - std.x)) < 0.05


def test_first_estimates_equal_the_standard_jacobians_at_the_first_step():
    """Before any estimate moved, the first estimates are the current ones."""
    rng = np.random.default_rng(5)
    R = np.tile(np.diag([SIGMA_R**2, SIGMA_A**2]), (3, 1, 1))
    filters = []
    for jac in ("current", "first-estimates"):
        ekf = EkfSlam(EkfConfig(jacobians=jac, merge_landmarks=False))
        ekf.initialize(np.zeros(3))
        ekf.add_landmarks(
            _measure(np.random.default_rng(1), np.zeros(3), WALLS), R, np.zeros((3, 2, 2))
        )
        ekf.update(np.arange(3), _measure(rng, np.zeros(3), WALLS), R)
        filters.append(ekf)
        rng = np.random.default_rng(5)
    a, b = filters
    np.testing.assert_array_equal(a.H, b.H)
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(a.P, b.P)


@pytest.mark.parametrize("jacobians", ["first-estimates", "observability-constrained"])
def test_first_estimates_follow_landmark_merges_and_the_filterpy_reference(jacobians):
    """Merging drops the removed landmark's first estimate; the dense reference agrees."""
    rng = np.random.default_rng(2)
    R2 = np.tile(np.diag([SIGMA_R**2, SIGMA_A**2]), (2, 1, 1))
    ekf = EkfSlam(EkfConfig(jacobians=jacobians))
    ekf.initialize(np.zeros(3))
    wall = WALLS[:1]
    ends = np.array([[[4.0, -1.0], [4.0, 0.0]], [[4.0, 0.1], [4.0, 1.0]]])
    two = np.vstack([_measure(rng, np.zeros(3), wall), _measure(rng, np.zeros(3), wall)])
    ekf.add_landmarks(two, R2, ends)
    first = [f.copy() for f in ekf._lm_first]
    np.testing.assert_array_equal(np.array(first), ekf.landmarks_r_alpha)
    assert ekf.merge_landmarks() == 1
    assert len(ekf._lm_first) == ekf.n_landmarks == 1
    np.testing.assert_array_equal(ekf._lm_first[0], first[0])  # the kept one's own
    assert not np.allclose(ekf._lm_first[0], ekf.landmarks_r_alpha[0])  # not the merged value
    dense = EkfSlam(EkfConfig(jacobians=jacobians, update_impl="filterpy"))
    dense.set_state(ekf.x.copy(), ekf.P.copy())
    dense._lm_first = [row.copy() for row in ekf._lm_first]
    for f in (ekf, dense):
        f.predict(np.array([0.3, 0.0, 0.1]), np.diag([1e-3, 1e-3, 1e-4]))
    z = _measure(rng, np.array([0.3, 0.0, 0.1]), wall)
    ekf.update(np.array([0]), z, R2[:1])
    dense.update(np.array([0]), z, R2[:1])
    np.testing.assert_allclose(dense.x, ekf.x, atol=1e-12)
    np.testing.assert_allclose(dense.P, ekf.P, atol=1e-12)


def test_oc_jacobians_are_the_closest_that_see_no_unobservable_direction():
    """``H* U = 0``; an ``H`` with ``H U = 0`` is kept; the FEJ ``H`` (which also has ``H U =
    0``) is never closer to the current one."""
    rng = np.random.default_rng(8)
    pose_first, pose_now = np.array([3.0, -2.0, 0.4]), np.array([3.05, -1.97, 0.43])
    first = WALLS + rng.normal(0.0, [0.05, 0.1], size=WALLS.shape)  # first estimates, far off
    x = np.r_[pose_now, WALLS.ravel()]
    z = _measure(rng, pose_now, WALLS)
    R = np.tile(np.diag([SIGMA_R**2, SIGMA_A**2]), (3, 1, 1))
    idx = np.arange(3)
    current = line_measurements(x, idx, z, R)
    oc = observability_constrained(current, pose_first, first[:, 1])
    fej = line_measurements(x, idx, z, R, (pose_first, first))
    N_pose, N_lm = unobservable_directions(pose_first, first[:, 1])
    for i in range(3):
        U = np.vstack([N_pose, N_lm[i]])
        cols = np.r_[0:3, 3 + 2 * i, 4 + 2 * i]
        H_oc = oc.H_sub[2 * i : 2 * i + 2][:, cols]
        H_fej = fej.H_sub[2 * i : 2 * i + 2][:, cols]
        H_cur = current.H_sub[2 * i : 2 * i + 2][:, cols]
        np.testing.assert_allclose(H_oc @ U, 0.0, atol=1e-12)
        np.testing.assert_allclose(H_fej @ U, 0.0, atol=1e-12)  # FEJ meets it too
        assert np.linalg.norm(H_oc - H_cur) < np.linalg.norm(H_fej - H_cur)
    again = observability_constrained(oc, pose_first, first[:, 1])
    np.testing.assert_allclose(again.H_sub, oc.H_sub, atol=1e-12)  # a projection
    np.testing.assert_array_equal(oc.y, current.y)  # the innovation is the current one


def test_unknown_jacobians_are_rejected():
    with pytest.raises(ConfigError, match=r"ekf\.jacobians"):
        EkfConfig(jacobians="latest")  # type: ignore[arg-type]
