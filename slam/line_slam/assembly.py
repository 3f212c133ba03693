"""The result of a run: every scan's pose, covariances, and the line map with its segments.

* **Scan poses.**  Keyframes as estimated; a scan between keyframes ``k`` and ``k+1`` is
  ``x_k ∘ δ_s ∘ Exp(f·Log(C))`` with ``δ_s`` its odometry since ``k``,
  ``C = δ_{k+1}⁻¹ (x_k⁻¹ x_{k+1})`` the correction the estimate made to the odometry between
  the two keyframes and ``f`` the fraction of that stretch already driven (path, turning
  weighted by :data:`~slam.line_slam.keyframes.ANGLE_WEIGHT_M_PER_RAD`).  After the last
  keyframe: ``x_k ∘ δ_s``.  A scan matched against its keyframe
  (``scan_matching.between_keyframes``, the default, where the match is accepted) is
  ``x_k ∘ δ_s`` with ``δ_s`` the match.
* **Covariances** (``pose_covariances = "keyframes"``): each keyframe's marginal from the
  back-end; a non-keyframe scan's is its keyframe's moved along ``δ_s`` (adjoint) plus the
  motion noise of ``δ_s`` (a matched scan: the match's covariance).  Reported in the output
  frame of the input policy.
* **Map.**  Landmarks with at least ``map_min_observations`` measurements, in normal form
  ``(r ≥ 0, α)`` with their marginal covariances; their visible segments are the union of the
  observed pieces (gaps up to ``map_segment_gap_m`` bridged), each end's variance including
  the pose uncertainty along the line.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from linefit.line import wrap_angle
from slam import interrupts
from slam.geometry import (
    adjoint_pose2,
    pose_between,
    pose_compose,
    pose_exp,
    pose_inverse,
    pose_log,
)
from slam.graph.backend import BatchBackend, Isam2Backend
from slam.graph.problem import LineGraph
from slam.inputs import InputPolicy
from slam.line_slam.config import SlamConfig
from slam.line_slam.keyframes import ANGLE_WEIGHT_M_PER_RAD, KeyframeTrack
from slam.lines import unite_segments
from slam.models.anchored import anchored_jacobian, landmarks_normal_form
from slam.models.motion import MotionNoiseConfig
from slam.result import SlamResult

__all__ = ["assemble_result", "landmark_segments", "scan_poses"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


def scan_poses(graph: LineGraph, track: KeyframeTrack) -> tuple[FloatArray, IntArray, FloatArray]:
    """Pose of every scan (module docstring), its keyframe and its odometry offset from it."""
    g = graph
    n = track.n_scans
    kf = np.asarray(track.scan_keyframe, dtype=np.intp)
    offsets = np.array(track.scan_offset).reshape(n, 3)
    if n == 0:
        return np.zeros((0, 3)), kf, offsets
    poses = pose_compose(g.poses[kf], offsets)
    nxt = kf + 1
    has_next = (
        (nxt < g.n_poses) & ~np.asarray(track.scan_is_keyframe, dtype=bool) & ~track.scan_matched
    )
    if np.any(has_next):
        k = kf[has_next]
        d_next = track.keyframe_delta[k + 1]
        est = pose_between(g.poses[k], g.poses[k + 1])
        corr = pose_log(pose_between(d_next, est))
        total = np.hypot(d_next[:, 0], d_next[:, 1]) + ANGLE_WEIGHT_M_PER_RAD * np.abs(d_next[:, 2])
        prog = np.asarray(track.scan_progress, dtype=float)[has_next]
        f = np.clip(prog / np.maximum(total, 1e-9), 0.0, 1.0)
        poses[has_next] = pose_compose(poses[has_next], pose_exp(f[:, None] * corr))
    poses[:, 2] = np.asarray(wrap_angle(poses[:, 2]))
    return poses, kf, offsets


def landmark_segments(
    graph: LineGraph,
    ids: IntArray,
    la_nf: FloatArray,
    kf_cov: FloatArray | None,
    gap_m: float,
) -> tuple[list[FloatArray], list[FloatArray]]:
    """Visible pieces of each map line ``ids``: its observations' intervals, united."""
    g = graph
    if g.n_line_factors == 0 or ids.size == 0:
        return [np.zeros((0, 2, 2)) for _ in ids], [np.zeros((0, 2)) for _ in ids]
    pf = g.piece_factor
    fp = g.factor_pose[pf]
    ends = np.concatenate([g.piece_ends, np.zeros((pf.shape[0], 2, 1))], axis=-1)
    pts = pose_compose(np.broadcast_to(g.poses[fp][:, None, :], ends.shape), ends)[..., :2]
    pos = np.full(g.n_landmarks, -1)
    pos[ids] = np.arange(ids.size)
    row = pos[g.factor_landmark[pf]]
    keep = row >= 0
    a = la_nf[row[keep], 1]
    r = la_nf[row[keep], 0]
    t = np.stack([-np.sin(a), np.cos(a)], -1)
    nrm = np.stack([np.cos(a), np.sin(a)], -1)
    s = np.einsum("fkd,fd->fk", pts[keep], t)
    lo, hi = s.min(axis=1), s.max(axis=1)
    var = g.piece_var[keep]
    if kf_cov is not None:
        th = g.poses[fp[keep], 2]
        c, sn = np.cos(th), np.sin(th)
        Rw = np.stack([np.stack([c, -sn], -1), np.stack([sn, c], -1)], -2)
        Pw = Rw @ kf_cov[fp[keep], :2, :2] @ np.swapaxes(Rw, 1, 2)
        var = var + np.einsum("fi,fij,fj->f", t, Pw, t)[:, None]
    order = np.argsort(row[keep], kind="stable")
    rows = row[keep][order]
    bounds = np.searchsorted(rows, np.arange(ids.size + 1))
    seg_out, var_out = [], []
    for k in range(ids.size):
        sel = order[bounds[k] : bounds[k + 1]]
        united, uvar = unite_segments(np.column_stack([lo[sel], hi[sel]]), var[sel], gap_m)
        foot = r[sel[0]] * nrm[sel[0]]
        ends = foot[None, None, :] + united[:, :, None] * t[sel[0]][None, None, :]
        seg_out.append(ends)
        var_out.append(uvar)
    return seg_out, var_out


def assemble_result(
    graph: LineGraph,
    backend: BatchBackend | Isam2Backend,
    track: KeyframeTrack,
    config: SlamConfig,
    policy: InputPolicy,
    stats: dict[str, Any],
    motion: MotionNoiseConfig | None = None,
    covariances: tuple[Any, LineGraph] | None = None,
) -> SlamResult:
    """The run's :class:`~slam.result.SlamResult` (module docstring).

    ``stats`` becomes the result's statistics (the same dict: the caller may complete it);
    ``motion`` is the odometry noise for non-keyframe scans (default ``config.motion``);
    ``covariances``: the back-end and graph the keyframes' and landmarks' covariances come
    from (default ``backend`` and ``graph``; a graph with the same poses and landmark
    indices, e.g. with passes linked to their walls, :mod:`slam.line_slam.passes`).
    """
    cov_backend, cov_graph = covariances if covariances is not None else (backend, graph)
    g = graph
    n = track.n_scans
    poses, kf, offsets = scan_poses(g, track)
    cov = np.full((n, 3, 3), np.nan)
    kf_cov = None
    if config.pose_covariances == "keyframes" and g.n_poses:
        kf_cov = cov_backend.pose_covariances(cov_graph, np.arange(g.n_poses))
        F = adjoint_pose2(pose_inverse(offsets))
        noise = np.where(
            track.scan_matched[:, None, None],
            np.asarray(track.scan_offset_cov).reshape(n, 3, 3),
            (motion or config.motion).covariance(offsets),
        )
        cov = F @ kf_cov[kf] @ np.swapaxes(F, 1, 2) + np.where(
            np.asarray(track.scan_is_keyframe)[:, None, None], 0.0, noise
        )
    interrupts.check()  # between the covariance blocks (slam.interrupts)
    poses, cov_out = policy.report(poses, cov)
    assert cov_out is not None
    counts = g.observation_counts()
    ids = np.flatnonzero(g.landmark_alive & (counts >= config.map_min_observations))
    la = g.landmarks_r_alpha[ids]
    lcov = cov_backend.landmark_covariances(cov_graph, ids) if ids.size else np.zeros((0, 2, 2))
    J = anchored_jacobian(g.landmarks[ids], g.anchors[ids])
    lcov = J @ lcov @ np.swapaxes(J, 1, 2)
    interrupts.check()
    la_nf, lcov_nf = landmarks_normal_form(la, lcov)
    assert lcov_nf is not None
    segs, seg_var = landmark_segments(g, ids, la_nf, kf_cov, config.map_segment_gap_m)
    return SlamResult(
        timestamps=np.asarray(track.timestamps, dtype=float),
        poses_world_laser=poses,
        pose_covariances=cov_out,
        is_keyframe=np.asarray(track.scan_is_keyframe, dtype=bool),
        keyframe_of_scan=kf.astype(np.int64),
        landmark_ids=ids.astype(np.int64),
        landmarks_r_alpha=la_nf,
        landmark_covariances=lcov_nf,
        landmark_segments=segs,
        landmark_segments_var=seg_var,
        landmark_n_observations=counts[ids],
        scan_runtime_s=np.asarray(track.scan_runtime_s, dtype=float),
        n_landmarks=np.asarray(track.scan_n_landmarks, dtype=np.int64),
        stats=stats,
        frame=policy.output_frame,
    )
