"""The simulated laser noise matches the paper's model (Section II, Eqs. 3-4) statistically.

Set-up: the laser at the origin, heading 0, in front of the wall x = D; many scans from the same
pose.  A beam reported at bearing Φ whose true ray left at Φ + ε_φ reads
``d = D / cos(Φ + ε_φ) + ε_d``.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from slam.sim import LaserConfig, LaserNoiseConfig, SimConfig, World
from slam.sim.simulate import simulate
from slam.sim.trajectory import SimTrajectory

D = 5.0
N_SCANS = 200


def _log(sigma_d: float, sigma_phi: float, seed: int = 3):
    world = World(np.array([[[D, -100.0], [D, 100.0]]]), np.array([42]), ("wall",))
    traj = SimTrajectory(1000.0 + 0.1 * np.arange(N_SCANS), np.zeros((N_SCANS, 3)))
    config = SimConfig(
        laser=LaserConfig(n_beams=121, first_angle_deg=-60.0, step_deg=1.0),
        noise=LaserNoiseConfig(sigma_range_m=sigma_d, sigma_bearing_rad=sigma_phi),
    )
    return simulate(world, traj, config, seed=seed)


def _chi2_ok(sum_sq: float, dof: int) -> bool:
    lo, hi = stats.chi2.ppf([0.0005, 0.9995], dof)
    return bool(lo < sum_sq < hi)


def test_noise_free_scan_is_exact():
    log = _log(0.0, 0.0)
    expected = np.broadcast_to(D / np.cos(log.bearings_rad), log.ranges_m.shape)
    np.testing.assert_allclose(log.ranges_m, expected, rtol=1e-14)
    assert (log.hit_ids == 42).all()


def test_range_noise_has_sigma_d():
    sigma_d = 0.005
    log = _log(sigma_d, 0.0)
    res = (log.ranges_m - D / np.cos(log.bearings_rad)[None, :]).ravel()
    n = res.size
    assert abs(res.mean()) < 4.0 * sigma_d / np.sqrt(n)
    assert _chi2_ok(float(((res - res.mean()) ** 2).sum() / sigma_d**2), n - 1)
    # Independent across beams and scans: neighbouring residuals uncorrelated.
    r = res.reshape(N_SCANS, -1)
    corr = np.corrcoef(r[:, :-1].ravel(), r[:, 1:].ravel())[0, 1]
    assert abs(corr) < 4.0 / np.sqrt(r[:, 1:].size)


def test_bearing_noise_moves_the_hit_along_the_wall_with_sigma_phi():
    """σ_d = 0: the hit lies on the wall, displaced along it by D/cos²Φ·ε_φ (to first order)."""
    sigma_phi = 1e-3
    log = _log(0.0, sigma_phi)
    phi = log.bearings_rad
    side = np.abs(phi) >= np.deg2rad(10.0)  # the sign of Φ + ε_φ is that of Φ
    d = log.ranges_m[:, side]
    # Where the true ray met the wall: the wall point at distance d from the laser.
    y_hit = np.sign(phi[side]) * np.sqrt(d**2 - D**2)
    eps = np.arctan2(y_hit, D) - phi[side]  # recovered bearing error, exact
    n = eps.size
    assert abs(eps.mean()) < 4.0 * sigma_phi / np.sqrt(n)
    assert _chi2_ok(float(((eps - eps.mean()) ** 2).sum() / sigma_phi**2), n - 1)
    # The along-wall displacement against its first-order standard deviation D/cos²Φ·σ_φ.
    disp = y_hit - D * np.tan(phi[side])
    z = disp / (D / np.cos(phi[side]) ** 2 * sigma_phi)
    assert _chi2_ok(float((z**2).sum()), n)
    # The reported bearing is Φ (the log has no way to carry ε_φ): the reading is a range only.
    assert log.bearings_rad[0] == pytest.approx(np.deg2rad(-60.0))


def test_both_noises_give_the_eq8_covariance_along_the_wall_normal():
    """Normal residual of the reported point: var = cos²Φ·σ_d² + D²·tan²Φ·σ_φ² (Eq. 8)."""
    sigma_d, sigma_phi = 0.005, 1e-3
    log = _log(sigma_d, sigma_phi, seed=11)
    phi = log.bearings_rad[None, :]
    normal_res = log.ranges_m * np.cos(phi) - D
    var = np.cos(phi) ** 2 * sigma_d**2 + (D * np.tan(phi)) ** 2 * sigma_phi**2
    z2 = normal_res**2 / var
    assert _chi2_ok(float(z2.sum()), z2.size)
    # Per beam direction as well (a wrong weighting of the two terms fails at the edges).
    per_beam = z2.sum(axis=0)
    lo, hi = stats.chi2.ppf([0.0005 / 121, 1 - 0.0005 / 121], N_SCANS)
    assert ((per_beam > lo) & (per_beam < hi)).all()


def test_true_ranges_and_hit_ids_are_consistent():
    log = _log(0.005, 1e-4)
    assert (log.hit_ids == 42).all()
    assert np.abs(log.ranges_m - log.true_ranges_m).max() < 6 * 0.005
