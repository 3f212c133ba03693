"""Why iSAM2's pose covariances are larger than the batch solver's: a controlled experiment.

Seeded runs of the line-level simulator (``lineslam consistency``'s data: the corridor loop,
exact noise models, the default Cauchy kernel), each through ``LineSlam`` with the iSAM2 and
with the batch back-end.  For every iSAM2 run the pose NEES is then recomputed with the
covariances taken in different ways, each changing one thing, at the same estimate:

* ``isam2``: iSAM2's own marginals (its Bayes tree), as the run reports them without the
  final weight refresh (``[slam.isam2] final_weight_refresh = false``);
* ``theta``: the whole graph linearised at iSAM2's linearisation point ``θ`` with the IRLS
  weights at ``θ`` (``gtsam.Marginals``) — what the Bayes tree holds;
* ``J@est,w@θ``: Jacobians at the estimate ``θ ⊕ δ``, weights at ``θ``;
* ``J@θ,w@est``: Jacobians at ``θ``, weights at the estimate;
* ``estimate``: both at the estimate (what the batch back-end reports for its own estimate);
* ``gauss``: at the estimate without the kernel's weights (all ``w = 1``);
* ``restart``: iSAM2 rebuilt at the estimate once more (``Isam2Solver.restart``: every block
  relinearised, weights refreshed, one Gauss-Newton step), its own marginals and its new
  estimate — what ``final_weight_refresh`` (the default) does; ``restart×2``: twice;
* ``batch``: the batch back-end's own run (its own estimate and marginals).

Also printed: the mean IRLS weight of the line factors at ``θ`` and at the estimate, and how
far ``θ`` is from the estimate.

    PYTHONPATH=. .venv/bin/python scripts/study_isam2_covariance.py [--runs 20] [--loops 1]
"""

from __future__ import annotations

import argparse
import time
import warnings
from dataclasses import replace
from typing import Any

from slam import blas as _blas  # noqa: F401  # isort: skip  (before numpy: slam.blas)
import gtsam
import numpy as np

from slam.config import RunConfig
from slam.evaluation import nees_bounds, pose_nees_values
from slam.experiments.linesim import (
    LineSimConfig,
    lineset_to_lines,
    matched_run_config,
    simulate_line_run,
    world_and_trajectory,
)
from slam.experiments.parallel import task_seed
from slam.geometry import adjoint_pose2, pose_inverse
from slam.graph import factors as factors_module
from slam.graph.batch import BatchSolver
from slam.graph.factors import linearize_line_factors
from slam.line_slam import LineSlam

VARIANTS = (
    "isam2",
    "theta",
    "J@est,w@θ",
    "J@θ,w@est",
    "estimate",
    "gauss",
    "restart",
    "restart×2",
    "batch",
)


def run_slam(backend: str, run: Any, run_config: RunConfig) -> LineSlam:
    """LineSlam with ``backend`` over a simulated run (optimised).

    iSAM2 runs without the final weight refresh (``Isam2Config.final_weight_refresh``): the
    ``restart`` variant below is that refresh.
    """
    cfg = replace(run_config.slam, backend=backend)
    cfg = replace(cfg, isam2=replace(cfg.isam2, final_weight_refresh=False))
    slam = LineSlam(cfg, run_config.linefit)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for scan, lines in zip(run.scans, run.lines, strict=True):
            slam.add_scan(scan, lineset_to_lines(lines))
        slam.optimize()
    return slam


def scan_covariances(slam: LineSlam, kf_cov: np.ndarray) -> np.ndarray:
    """Every scan's covariance from keyframe covariances, as ``assemble_result`` does."""
    track = slam.track
    kf = np.asarray(track.scan_keyframe, dtype=np.intp)
    offsets = np.array(track.scan_offset).reshape(-1, 3)
    F = adjoint_pose2(pose_inverse(offsets))
    Q = slam.odometry_noise.model.covariance(offsets)
    is_kf = np.asarray(track.scan_is_keyframe)[:, None, None]
    return np.asarray(F @ kf_cov[kf] @ np.swapaxes(F, 1, 2) + np.where(is_kf, 0.0, Q))


def marginals_at(
    slam: LineSlam,
    jac_poses: np.ndarray,
    jac_lms: np.ndarray,
    w_poses: np.ndarray | None,
    w_lms: np.ndarray | None,
    kernel: str | None = None,
) -> np.ndarray:
    """Keyframe marginals of the graph linearised at ``jac_*`` with IRLS weights from ``w_*``.

    ``w_* = None``: the weights where the Jacobians are; ``kernel="none"``: no weights.
    """
    g = slam.graph
    cfg = slam.config.solver
    if kernel is not None:
        cfg = replace(cfg, robust_kernel=kernel)
    solver = BatchSolver(cfg)
    original = factors_module.linearize_line_factors
    if w_poses is not None:
        fp, lm = g.factor_pose, g.factor_landmark
        at_w = linearize_line_factors(
            w_poses[fp],
            w_lms[lm],
            g.anchors[lm],
            g.factor_z,
            g.factor_sqrt_info,
            cfg.robust_kernel,
            cfg.robust_k,
        )
        weights = at_w.weights

        def with_weights(*args: Any, **kwargs: Any) -> Any:
            lin = original(*args[:5], "none", 1.0)
            s = np.sqrt(weights)
            return factors_module.LineLinearization(
                lin.A_pose * s[:, None, None],
                lin.A_landmark * s[:, None, None],
                lin.b * s[:, None],
                lin.whitened_residual,
                weights,
            )

        import slam.graph.batch as batch_module

        batch_module.linearize_line_factors = with_weights  # type: ignore[assignment]
        try:
            gfg = solver.linearize(g, jac_poses, jac_lms)
        finally:
            batch_module.linearize_line_factors = original  # type: ignore[assignment]
    else:
        gfg = solver.linearize(g, jac_poses, jac_lms)
    marg = gtsam.Marginals(gfg, gtsam.VectorValues())
    from slam.graph.linear import keys_of

    keys = keys_of("x", np.arange(g.n_poses))
    return np.array([marg.marginalCovariance(k) for k in keys])


def mean_weight(slam: LineSlam, poses: np.ndarray, lms: np.ndarray) -> float:
    g = slam.graph
    fp, lm = g.factor_pose, g.factor_landmark
    alive = g.landmark_alive[lm]
    lin = linearize_line_factors(
        poses[fp],
        lms[lm],
        g.anchors[lm],
        g.factor_z,
        g.factor_sqrt_info,
        slam.config.solver.robust_kernel,
        slam.config.solver.robust_k,
    )
    return float(np.mean(lin.weights[alive]))


def study_run(seed: int, world: Any, truth: np.ndarray, run_config: RunConfig) -> dict[str, Any]:
    sim = LineSimConfig()
    run = simulate_line_run(world, truth, sim, seed=seed)
    cfg = matched_run_config(run_config, sim)
    out: dict[str, Any] = {}
    t0 = time.perf_counter()
    isam = run_slam("isam2", run, cfg)
    res = isam.result()
    n = res.n_scans
    nees: dict[str, float] = {}

    def score(poses: np.ndarray, cov: np.ndarray) -> float:
        return float(np.nanmean(pose_nees_values(poses, cov, truth[:n])))

    nees["isam2"] = score(res.poses_world_laser, res.pose_covariances)
    solver = isam.backend.solver  # type: ignore[union-attr]
    solver._refresh_theta()
    g = isam.graph
    th_p = solver._theta_poses.data.copy()
    th_l = solver._theta_lms.data.copy()
    est_p, est_l = g.poses.copy(), g.landmarks.copy()
    poses = res.poses_world_laser
    variants = {
        "theta": (th_p, th_l, None, None, None),
        "J@est,w@θ": (est_p, est_l, th_p, th_l, None),
        "J@θ,w@est": (th_p, th_l, est_p, est_l, None),
        "estimate": (est_p, est_l, None, None, None),
        "gauss": (est_p, est_l, None, None, "none"),
    }
    for name, (jp, jl, wp, wl, kernel) in variants.items():
        kf_cov = marginals_at(isam, jp, jl, wp, wl, kernel)
        nees[name] = score(poses, scan_covariances(isam, kf_cov))
    d = th_p - est_p
    out["theta_offset_mm"] = float(1000 * np.max(np.hypot(d[:, 0], d[:, 1])))
    out["weight_theta"] = mean_weight(isam, th_p, th_l)
    out["weight_estimate"] = mean_weight(isam, est_p, est_l)
    solver.restart(g)  # iSAM2 rebuilt at the estimate: one GN step with fresh weights
    res_r = isam.result()
    nees["restart"] = score(res_r.poses_world_laser, res_r.pose_covariances)
    solver.restart(g)
    res_r2 = isam.result()
    nees["restart×2"] = score(res_r2.poses_world_laser, res_r2.pose_covariances)
    batch = run_slam("batch", run, cfg)
    res_b = batch.result()
    nees["batch"] = score(res_b.poses_world_laser, res_b.pose_covariances)
    out["nees"] = nees
    e_i = res.poses_world_laser - truth[:n]
    e_b = res_b.poses_world_laser - truth[:n]
    e_r = res_r2.poses_world_laser - truth[:n]
    out["rmse_mm"] = {
        k: float(1000 * np.sqrt(np.mean(np.sum(e[:, :2] ** 2, axis=1))))
        for k, e in (("isam2", e_i), ("restart×2", e_r), ("batch", e_b))
    }
    out["time_s"] = time.perf_counter() - t0
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument("--world", default="corridor_loop")
    parser.add_argument("--loops", type=float, default=1.0)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    world, truth = world_and_trajectory(args.world, args.loops)
    run_config = RunConfig()
    rows = []
    for i in range(args.runs):
        r = study_run(task_seed(args.seed, i), world, truth, run_config)
        rows.append(r)
        print(
            f"run {i}: "
            + " ".join(f"{k} {v:.2f}" for k, v in r["nees"].items())
            + f" | w θ {r['weight_theta']:.3f} est {r['weight_estimate']:.3f}"
            + f" | θ off {r['theta_offset_mm']:.1f} mm | {r['time_s']:.1f} s",
            flush=True,
        )
    lo, hi = nees_bounds(3, len(rows), 0.95)
    print(
        f"\n{args.world} x{args.loops:g}, {len(rows)} runs, {truth.shape[0]} scans; mean pose "
        f"NEES over runs and scans (3 dof; 95 % band of a {len(rows)}-run average "
        f"[{lo:.2f}, {hi:.2f}])"
    )
    for name in VARIANTS:
        print(f"  {name:<11} {np.mean([r['nees'][name] for r in rows]):6.2f}")
    w_theta = np.mean([r["weight_theta"] for r in rows])
    w_est = np.mean([r["weight_estimate"] for r in rows])
    print(f"mean IRLS weight of the line factors: at θ {w_theta:.3f}, at the estimate {w_est:.3f}")
    print(
        f"largest |θ − estimate| per run (mm): median "
        f"{np.median([r['theta_offset_mm'] for r in rows]):.1f}"
    )
    for k in ("isam2", "restart×2", "batch"):
        print(f"position RMSE {k}: {np.mean([r['rmse_mm'][k] for r in rows]):.2f} mm")


if __name__ == "__main__":
    main()
