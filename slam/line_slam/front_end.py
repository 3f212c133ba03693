"""The front-end step of a keyframe: its lines registered against the local map.

The registration (:func:`slam.frontend.registration.register_lines`) estimates the keyframe's
pose from its lines and the local map, with the odometry prediction ``x̂ = x_k ∘ δ`` as a prior
(covariance: the motion noise plus ``frontend.prior_sigma_*``).  Its pairs are the data
association; its pose is the keyframe's initial estimate.  When too few lines match
(``frontend.relocalisation``), the lines are searched for in the local map around the
prediction (:func:`slam.frontend.loop_closure.search_loop_closure` with the window as a prior)
and registered again from the correction found; the registration with more pairs is kept.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from linefit.line import wrap_angle
from slam.frontend.config import FrontendConfig
from slam.frontend.loop_closure import LoopLines, search_loop_closure
from slam.frontend.registration import RegistrationResult, register_lines
from slam.geometry import pose_between
from slam.graph.problem import LineGraph
from slam.line_slam.local_map import LocalMap
from slam.line_slam.observations import ScanLines
from slam.lines.lineset import LineSet

__all__ = ["Registration", "add_registration_factor", "register_keyframe"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class Registration:
    """Outcome of :func:`register_keyframe`.

    Attributes
    ----------
    pose_world_laser : ndarray, shape (3,)
        The keyframe's initial estimate: the registered pose, else the prediction.
    cov : ndarray, shape (3, 3) or None
        The registered pose's covariance (None when the registration failed).
    matches : ndarray of int, shape (K,)
        For each line, the row of its local-map landmark, or −1.
    n_compatible : ndarray of int, shape (K,)
        Local-map landmarks compatible with each line (more than one: ambiguous).
    attempted : bool
        Whether there was anything to register against.
    relocalised : bool
        A relocalisation search ran; ``relocalisation_used``: its result was kept.
    """

    pose_world_laser: FloatArray
    cov: FloatArray | None
    matches: NDArray[np.int64]
    n_compatible: NDArray[np.int64]
    attempted: bool = False
    relocalised: bool = False
    relocalisation_used: bool = False

    @property
    def failed(self) -> bool:
        """Registration attempted but not enough lines matched."""
        return self.attempted and self.cov is None


def _prior(frontend: FrontendConfig) -> FloatArray:
    s_xy, s_th = frontend.prior_sigma_xy_m, frontend.prior_sigma_theta_rad
    return np.diag([s_xy**2, s_xy**2, s_th**2])


def register_keyframe(
    lines: ScanLines,
    local: LocalMap,
    x_pred: FloatArray,
    Q: FloatArray,
    frontend: FrontendConfig,
) -> Registration:
    """Register ``lines`` against ``local`` around the prediction ``x_pred`` (motion noise Q)."""
    K = len(lines)
    none = Registration(x_pred, None, np.full(K, -1, np.int64), np.zeros(K, np.int64))
    if K == 0 or len(local.lines) == 0:
        return none
    P0 = Q + _prior(frontend)
    scan_set = LineSet(lines.z, lines.R, lines.endpoints, np.arange(K))
    reg = register_lines(scan_set, local.lines, x_pred, P0, frontend.registration)
    rc = frontend.relocalisation
    relocalised = used = False
    if (
        rc.enabled
        and reg.n_matches < K
        and reg.n_matches < rc.min_matched_fraction * K
        and len(local.lines) >= rc.min_matches
    ):
        relocalised = True
        better = _relocalise(scan_set, local, x_pred, P0, reg, frontend)
        used = better is not None
        reg = better if better is not None else reg
    return Registration(
        reg.pose_world_laser if reg.matched else x_pred,
        reg.cov if reg.matched else None,
        reg.matches,
        reg.n_compatible,
        attempted=True,
        relocalised=relocalised,
        relocalisation_used=used,
    )


def _relocalise(
    scan_set: LineSet,
    local: LocalMap,
    x_pred: FloatArray,
    P0: FloatArray,
    reg: RegistrationResult,
    frontend: FrontendConfig,
) -> RegistrationResult | None:
    """Search the scan's lines in the local map around ``x_pred`` and register again.

    Returns the new registration when it pairs more lines than ``reg``, else None.
    """
    rc = frontend.relocalisation
    z = scan_set.r_alpha
    a_w = np.asarray(wrap_angle(z[:, 1] + x_pred[2]))
    r_w = z[:, 0] + x_pred[0] * np.cos(a_w) + x_pred[1] * np.sin(a_w)
    ends = scan_set.endpoints_in(x_pred)
    scan_ll = LoopLines(a_w, r_w, ends)
    map_ll = LoopLines.from_anchored(local.rho_phi, local.anchors, local.extents, local.side)
    found = search_loop_closure(
        scan_ll, map_ll, x_pred[:2], rc.window_xy_m, rc.window_theta_rad, rc, window_prior=True
    ).closure
    if found is None:
        return None
    t = found.correction
    x_new = np.array([x_pred[0] + t[0], x_pred[1] + t[1], float(wrap_angle(x_pred[2] + t[2]))])
    reg2 = register_lines(
        scan_set, local.lines, x_new, _prior(frontend) + 0.1 * P0, frontend.registration
    )
    return reg2 if reg2.n_matches > reg.n_matches else None


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
