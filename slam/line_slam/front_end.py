"""The front-end step of a keyframe: its lines registered against the local map.

The registration (:func:`slam.frontend.registration.register_lines`) estimates the keyframe's
pose from its lines and the local map with the odometry prediction ``x̂ = x_k ∘ δ`` as a prior
(covariance ``P₀``: the motion noise ``Q(δ)`` plus ``frontend.prior_sigma_*``).  Its pairs are
the data association; its pose is the keyframe's initial estimate.

**Never worse than the odometry.**  Under the models, the registration's correction
``c = x_reg ⊖ x̂`` is Gaussian with covariance ``P₀ − P_post`` (``P_post`` the registration's
posterior); its squared Mahalanobis distance, taken on the directions the lines constrain (a
pseudo-inverse: along parallel walls the correction is the prior's, zero), must lie within the
``frontend.consistency_probability`` quantile of χ² (as many degrees of freedom as constrained
directions).  A correction beyond it means a wrong pairing or an odometry step the model does not
explain; the registration is not used as it is.

**Relocalisation.**  When too few lines pair (``relocalisation.min_matched_fraction``) or the
correction fails the test, the lines are searched for in the local map over a window of
``relocalisation.window_sigmas`` standard deviations of ``P₀`` around the prediction
(:func:`slam.frontend.loop_closure.search_loop_closure`, the window as a prior), and registered
again from the correction found — with the same prior ``(x̂, P₀)``, so the same test applies.
If neither registration passes, the keyframe rests on the odometry.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from linefit.line import wrap_angle
from slam.frontend.config import FrontendConfig
from slam.frontend.loop_closure import LoopLines, search_loop_closure
from slam.frontend.registration import RegistrationResult, register_lines
from slam.geometry import pose_between, pose_log
from slam.graph.problem import LineGraph
from slam.line_slam.local_map import LocalMap
from slam.line_slam.observations import ScanLines
from slam.lines.lineset import LineSet
from slam.lines.merge import chi2_ppf

__all__ = [
    "Registration",
    "add_registration_factor",
    "correction_consistency",
    "register_keyframe",
]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class Registration:
    """Outcome of :func:`register_keyframe`.

    Attributes
    ----------
    pose_world_laser : ndarray, shape (3,)
        The keyframe's initial estimate: the registered pose, else the prediction.
    cov : ndarray, shape (3, 3) or None
        The registered pose's covariance (None when no registration is used).
    prior_cov : ndarray, shape (3, 3)
        ``P₀``, the prediction's covariance.
    matches : ndarray of int, shape (K,)
        For each line, the row of its local-map landmark, or −1.
    n_compatible : ndarray of int, shape (K,)
        Local-map landmarks compatible with each line (more than one: ambiguous).
    correction : ndarray, shape (3,)
        ``x_reg ⊖ x̂`` of the registration used (zero when none).
    correction_chi2 : float
        Its squared Mahalanobis distance (NaN when no registration was tried).
    attempted : bool
        Whether there was anything to register against.
    rejected : bool
        A registration paired enough lines but failed the consistency test (and no
        relocalisation passed it).
    relocalised : bool
        A relocalisation search ran; ``relocalisation_used``: its result was kept.
    """

    pose_world_laser: FloatArray
    cov: FloatArray | None
    prior_cov: FloatArray
    matches: NDArray[np.int64]
    n_compatible: NDArray[np.int64]
    correction: FloatArray
    correction_chi2: float = float("nan")
    attempted: bool = False
    rejected: bool = False
    relocalised: bool = False
    relocalisation_used: bool = False

    @property
    def failed(self) -> bool:
        """Registration attempted but not used (too few pairs, or inconsistent)."""
        return self.attempted and self.cov is None


def _prior(frontend: FrontendConfig) -> FloatArray:
    s_xy, s_th = frontend.prior_sigma_xy_m, frontend.prior_sigma_theta_rad
    return np.diag([s_xy**2, s_xy**2, s_th**2])


def correction_consistency(
    correction: FloatArray, prior_cov: FloatArray, posterior_cov: FloatArray
) -> tuple[float, int]:
    """Squared Mahalanobis distance of a MAP correction and its degrees of freedom.

    ``c ~ N(0, P₀ − P_post)`` under the models; directions the measurements do not constrain
    (eigenvalues of ``P₀ − P_post`` below 1 % of ``P₀``'s) are left out.
    """
    P0 = np.asarray(prior_cov, dtype=float)
    D = P0 - np.asarray(posterior_cov, dtype=float)
    D = 0.5 * (D + D.T)
    # whiten by P₀ so that "small" is relative to the prior in every direction
    L = np.linalg.cholesky(P0)
    Li = np.linalg.inv(L)
    w, V = np.linalg.eigh(Li @ D @ Li.T)
    keep = w > 1e-2
    if not np.any(keep):
        return 0.0, 0
    z = V[:, keep].T @ (Li @ np.asarray(correction, dtype=float))
    return float(np.sum(z**2 / w[keep])), int(np.count_nonzero(keep))


def _passes(
    reg: RegistrationResult, x_pred: FloatArray, P0: FloatArray, probability: float
) -> tuple[bool, FloatArray, float]:
    c = pose_log(pose_between(x_pred, reg.pose_world_laser))
    d2, dof = correction_consistency(c, P0, reg.cov)
    ok = dof == 0 or d2 <= chi2_ppf(probability, dof)
    return ok, c, d2


def register_keyframe(
    lines: ScanLines,
    local: LocalMap,
    x_pred: FloatArray,
    Q: FloatArray,
    frontend: FrontendConfig,
) -> Registration:
    """Register ``lines`` against ``local`` around the prediction ``x_pred`` (motion noise Q)."""
    K = len(lines)
    P0 = Q + _prior(frontend)
    none = Registration(
        x_pred, None, P0, np.full(K, -1, np.int64), np.zeros(K, np.int64), np.zeros(3)
    )
    if K == 0 or len(local.lines) == 0:
        return none
    p = frontend.consistency_probability
    scan_set = LineSet(lines.z, lines.R, lines.endpoints, np.arange(K))
    reg = register_lines(scan_set, local.lines, x_pred, P0, frontend.registration)
    ok, c, d2 = _passes(reg, x_pred, P0, p) if reg.matched else (False, np.zeros(3), np.nan)
    rc = frontend.relocalisation
    few = reg.n_matches < K and reg.n_matches < rc.min_matched_fraction * K
    relocalised = used = False
    if rc.enabled and (few or (reg.matched and not ok)) and len(local.lines) >= rc.min_matches:
        relocalised = True
        reg2 = _relocalise(scan_set, local, x_pred, P0, frontend)
        if reg2 is not None and reg2.matched:
            ok2, c2, d2_2 = _passes(reg2, x_pred, P0, p)
            if ok2 and (not ok or reg2.n_matches > reg.n_matches):
                reg, ok, c, d2, used = reg2, True, c2, d2_2, True
    accepted = reg.matched and ok
    return Registration(
        reg.pose_world_laser if accepted else x_pred,
        reg.cov if accepted else None,
        P0,
        reg.matches if accepted or not reg.matched else np.full(K, -1, np.int64),
        reg.n_compatible,
        c if accepted else np.zeros(3),
        d2,
        attempted=True,
        rejected=reg.matched and not ok,
        relocalised=relocalised,
        relocalisation_used=used,
    )


def _relocalise(
    scan_set: LineSet,
    local: LocalMap,
    x_pred: FloatArray,
    P0: FloatArray,
    frontend: FrontendConfig,
) -> RegistrationResult | None:
    """Search the scan's lines in the local map around ``x_pred``; register from what is found.

    The window is ``window_sigmas`` standard deviations of ``P₀`` (at least the configured
    minimum); the second registration keeps the prior ``(x_pred, P₀)``.
    """
    rc = frontend.relocalisation
    xy = P0[:2, :2]
    sigma_xy = float(np.sqrt(np.max(np.linalg.eigvalsh(xy))))
    window_xy = max(rc.window_sigmas * sigma_xy, rc.min_window_xy_m)
    window_th = max(rc.window_sigmas * float(np.sqrt(P0[2, 2])), rc.min_window_theta_rad)
    z = scan_set.r_alpha
    a_w = np.asarray(wrap_angle(z[:, 1] + x_pred[2]))
    r_w = z[:, 0] + x_pred[0] * np.cos(a_w) + x_pred[1] * np.sin(a_w)
    ends = scan_set.endpoints_in(x_pred)
    scan_ll = LoopLines(a_w, r_w, ends)
    map_ll = LoopLines.from_anchored(local.rho_phi, local.anchors, local.extents, local.side)
    found = search_loop_closure(
        scan_ll, map_ll, x_pred[:2], window_xy, window_th, rc, window_prior=True
    ).closure
    if found is None:
        return None
    t = found.correction
    x_new = np.array([x_pred[0] + t[0], x_pred[1] + t[1], float(wrap_angle(x_pred[2] + t[2]))])
    return register_lines(
        scan_set, local.lines, x_pred, P0, frontend.registration, initial_pose=x_new
    )


def add_registration_factor(
    graph: LineGraph, prev: int, i: int, reg: Registration, inflation: float
) -> None:
    """Relative-pose factor ``prev → i`` from the registration (inflated covariance).

    The registration's covariance is that of the absolute pose given the local map; as a
    relative pose from the previous keyframe (whose estimate the local map is tied to) it is
    used as is, times ``inflation`` (double counting with the line factors).
    """
    assert reg.cov is not None
    rel = pose_between(graph.poses[prev], reg.pose_world_laser)
    cov = inflation * np.asarray(reg.cov)
    graph.add_odometry(prev, i, rel, 0.5 * (cov + cov.T))
