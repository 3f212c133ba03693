"""Benchmark of the factor-graph back-end on synthetic problems (5 line factors per pose).

Side by side, in one run, at 250, 1000 and 4000 poses:

What each column times (process CPU time, all threads, best of several repetitions, so that
other jobs on a shared machine change the figures little; iSAM2 in wall-clock time; the problem
is at its solution, as in the later iterations of a solve):

* ``numpy`` / ``+JacF``: the fast path's linearisation of every line factor in numpy
  (``linearize_line_factors``, robust IRLS weights included) and the construction of the
  ``gtsam.JacobianFactor`` objects, each per line factor;
* ``lin/f``: ``BatchSolver.linearize`` of the whole graph, per factor (line factors +
  odometry factors + prior, the count used by every ``/f`` column); ``elim``: solving that
  linear system (``GaussianFactorGraph.optimize``, COLAMD ordering computed outside the
  timing); ``iter/f``: the two together, one whole Gauss-Newton
  iteration of the batch back-end, per factor;
* ``CF GN/f``: the same Gauss-Newton iteration (``NonlinearFactorGraph.linearize`` then
  ``GaussianFactorGraph.optimize``, same ordering method) over ``gtsam.CustomFactor`` line
  factors (a Python callback per factor) with the fast path's objective: the line factors'
  Gaussian noise wrapped in GTSAM's ``noiseModel.Robust`` with the solver's kernel (Cauchy,
  ``k`` from ``SolverConfig``); ``CF lin/f``: its linearisation alone;
* ``iSAM2``: the graph fed pose by pose (one ``ISAM2.update`` each, line factors as
  per-keyframe ``LinearContainerFactor`` blocks); mean time per update over the last 100
  updates, and the solver's own build/update split (means over all updates).

Prints the table and the growth of each per-factor cost from the smallest to the largest size
(target ≤ 1.5 for the fast path's whole iteration, elimination included).

    .venv/bin/python scripts/bench_graph.py [--sizes 250 1000 4000] [--no-isam2]
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path

import gtsam
import numpy as np

from slam.geometry import line_to_parent, pose_compose
from slam.graph import (
    BatchSolver,
    Isam2Solver,
    LineGraph,
    SolverConfig,
    line_custom_factor,
    synthetic_problem,
)
from slam.graph.factors import LineLinearization, linearize_line_factors
from slam.graph.linear import keys_of, line_jacobian_factors, native_odometry_factors


def one_factor_each(
    pose: np.ndarray, lm: np.ndarray, lin: LineLinearization
) -> list[gtsam.JacobianFactor]:
    """The unpacked construction: one 2-key ``JacobianFactor`` per line factor."""
    unit2 = gtsam.noiseModel.Unit.Create(2)
    return [
        gtsam.JacobianFactor(kx, ax, kl, al, b, unit2)
        for kx, ax, kl, al, b in zip(
            keys_of("x", pose), lin.A_pose, keys_of("l", lm), lin.A_landmark, lin.b, strict=True
        )
    ]


def best_of(fn: Callable[[], object], repeat: int) -> float:
    """Least process CPU time (s) of ``repeat`` calls of ``fn``."""
    times = []
    for _ in range(repeat):
        t0 = time.process_time()
        fn()
        times.append(time.process_time() - t0)
    return min(times)


def robust_noise(cov: np.ndarray, config: SolverConfig) -> gtsam.noiseModel.Base:
    """The line factor's Gaussian noise under the solver's robust kernel (GTSAM's own)."""
    base = gtsam.noiseModel.Gaussian.Covariance(np.asarray(cov, dtype=float))
    if config.robust_kernel == "none":
        return base
    est = gtsam.noiseModel.mEstimator
    kernel = (
        est.Cauchy.Create(config.robust_k)
        if config.robust_kernel == "cauchy"
        else est.Huber.Create(config.robust_k)
    )
    return gtsam.noiseModel.Robust.Create(kernel, base)


def custom_graph(
    g: LineGraph, config: SolverConfig
) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values]:
    nfg = native_odometry_factors(g)
    kx = keys_of("x", g.factor_pose)
    kl = keys_of("l", g.factor_landmark)
    for f in range(g.n_line_factors):
        nfg.add(
            line_custom_factor(
                kx[f],
                kl[f],
                g.anchors[g.factor_landmark[f]],
                g.factor_z[f],
                g.factor_cov[f],
                noise=robust_noise(g.factor_cov[f], config),
            )
        )
    values = gtsam.Values()
    for key, p in zip(keys_of("x", np.arange(g.n_poses)), g.poses, strict=True):
        values.insert(key, gtsam.Pose2(*p))
    for key, v in zip(keys_of("l", np.arange(g.n_landmarks)), g.landmarks, strict=True):
        values.insert(key, gtsam.Point2(*v))
    return nfg, values


def isam2_feed(src: LineGraph) -> tuple[float, float, float]:
    """Mean time per update over the last 100 updates, and build/update split (s)."""
    g = LineGraph()
    assert src.prior_pose is not None and src.prior_cov is not None
    g.set_prior(src.prior_pose, src.prior_cov)
    solver = Isam2Solver()
    times = []
    for i in range(src.n_poses):
        if i == 0:
            g.add_pose(src.prior_pose)
        else:
            g.add_pose(pose_compose(g.poses[i - 1], src.odometry_measured[i - 1]))
            g.add_odometry(i - 1, i, src.odometry_measured[i - 1], src.odometry_cov[i - 1])
        fs = np.flatnonzero(src.factor_pose == i)
        lms = src.factor_landmark[fs]
        new = np.arange(g.n_landmarks, lms.max() + 1)
        if new.size:
            first = np.array([fs[np.flatnonzero(lms == j)[0]] for j in new])
            z3 = np.column_stack([src.factor_z[first], np.zeros(new.size)])
            la = line_to_parent(z3, g.poses[i], normal_form=False)[0][:, :2]
            # anchors at the measured segments' mid-points seen from the current estimate
            mid = src.factor_endpoints[first].mean(axis=1)
            anchors = pose_compose(g.poses[i], np.column_stack([mid, np.zeros(new.size)]))
            g.add_landmarks(la, anchors[:, :2])
        g.add_line_factors(i, lms, src.factor_z[fs], src.factor_cov[fs], src.factor_endpoints[fs])
        t0 = time.perf_counter()
        solver.update(g)
        times.append(time.perf_counter() - t0)
    st = solver.stats
    return (
        float(np.mean(times[-100:])),
        st.time_s["build"] / st.updates,
        st.time_s["update"] / st.updates,
    )


def cpu_model() -> str:
    """CPU model and logical CPU count (Linux), for the record."""
    try:
        lines = Path("/proc/cpuinfo").read_text().splitlines()
    except OSError:
        return platform.machine()
    models = [ln.split(":", 1)[1].strip() for ln in lines if ln.startswith("model name")]
    return f"{models[0] if models else platform.machine()}, {len(models)} logical CPUs"


def gauss_newton_step(
    linearize: Callable[[], gtsam.GaussianFactorGraph], ordering: gtsam.Ordering
) -> gtsam.VectorValues:
    """One Gauss-Newton iteration: linearise, then eliminate and back-substitute."""
    return linearize().optimize(ordering)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[250, 1000, 4000])
    parser.add_argument("--no-isam2", action="store_true")
    args = parser.parse_args()
    print(f"machine: {cpu_model()}; load average {os.getloadavg()[0]:.2f} at start", flush=True)
    rows = []
    config = SolverConfig()
    for n in args.sizes:
        p = synthetic_problem(n, lines_per_pose=5, seed=1)
        g = p.graph
        solver = BatchSolver(config)
        solver.solve(g)  # benchmark at the solution, as in later iterations
        F = g.n_line_factors
        lm = g.factor_landmark

        def fast_numpy(g: LineGraph = g, lm: np.ndarray = lm) -> LineLinearization:
            return linearize_line_factors(
                g.poses[g.factor_pose],
                g.landmarks[lm],
                g.anchors[lm],
                g.factor_z,
                g.factor_sqrt_info,
            )

        lin = fast_numpy()
        t_np = best_of(fast_numpy, 5) / F
        t_jf = best_of(partial(line_jacobian_factors, g.factor_pose, lm, lin), 3) / F
        t_jf1 = best_of(partial(one_factor_each, g.factor_pose, lm, lin), 3) / F
        gfg = solver.linearize(g)
        n_factors = F + g.n_odometry + 1  # line factors, odometry, prior
        ordering = gtsam.Ordering.ColamdGaussianFactorGraph(gfg)
        t_lin = best_of(partial(solver.linearize, g), 3) / n_factors
        t_elim = best_of(partial(gfg.optimize, ordering), 3)
        t_iter = best_of(partial(gauss_newton_step, partial(solver.linearize, g), ordering), 3)
        nfg, values = custom_graph(g, config)
        reps = 1 if n >= 4000 else 2
        t_cf_lin = best_of(partial(nfg.linearize, values), reps) / nfg.size()
        cf_ordering = gtsam.Ordering.ColamdGaussianFactorGraph(nfg.linearize(values))
        t_cf_it = (
            best_of(partial(gauss_newton_step, partial(nfg.linearize, values), cf_ordering), reps)
            / nfg.size()
        )
        t_isam = (float("nan"),) * 3
        if not args.no_isam2:
            t_isam = isam2_feed(synthetic_problem(n, lines_per_pose=5, seed=1).graph)
        rows.append(
            (
                n,
                F,
                t_np,
                t_jf,
                t_lin,
                t_elim,
                t_iter / n_factors,
                t_cf_lin,
                t_cf_it,
                *t_isam,
                t_jf1,
            )
        )
        print(f"done {n} poses", flush=True)

    print()
    print(
        f"{'poses':>6} {'line f.':>8} | {'numpy':>7} {'+JacF':>7} {'lin/f':>7} {'elim':>7}"
        f" {'iter/f':>7} | {'CF lin/f':>8} {'CF GN/f':>8} | {'iSAM2/upd':>9} {'build':>7}"
        f" {'update':>7}"
    )
    print(
        f"{'':>6} {'':>8} | {'µs/f':>7} {'µs/f':>7} {'µs/f':>7} {'ms':>7} {'µs/f':>7} |"
        f" {'µs/f':>8} {'µs/f':>8} | {'ms':>9} {'ms':>7} {'ms':>7}"
    )
    for n, F, t_np, t_jf, t_li, t_el, t_it, t_cfl, t_cfi, t_up, t_b, t_u, _ in rows:
        print(
            f"{n:>6} {F:>8} | {1e6 * t_np:7.2f} {1e6 * t_jf:7.2f} {1e6 * t_li:7.2f}"
            f" {1e3 * t_el:7.1f} {1e6 * t_it:7.2f} | {1e6 * t_cfl:8.1f} {1e6 * t_cfi:8.1f} |"
            f" {1e3 * t_up:9.2f} {1e3 * t_b:7.2f} {1e3 * t_u:7.2f}"
        )
    if len(rows) > 1:
        a, b = rows[0], rows[-1]
        fast_a, fast_b = a[2] + a[3], b[2] + b[3]
        print()
        print(
            f"line-factor linearisation (numpy + JacobianFactor) per line factor, {b[0]} vs"
            f" {a[0]} poses: {fast_b / fast_a:.2f}x"
        )
        print(
            f"whole batch Gauss-Newton iteration per factor (linearise + eliminate), {b[0]} vs"
            f" {a[0]} poses: {b[6] / a[6]:.2f}x (target <= 1.5)"
        )
        for r in rows:
            print(
                f"JacobianFactors per line factor at {r[0]} poses: packed {1e6 * r[3]:.2f} µs,"
                f" one each {1e6 * r[12]:.2f} µs ({r[12] / r[3]:.2f}x)"
            )
        print(
            f"CustomFactor Gauss-Newton iteration per factor, {b[0]} vs {a[0]} poses:"
            f" {b[8] / a[8]:.2f}x"
        )
        for r in rows:
            print(
                f"CustomFactor / fast path, one Gauss-Newton iteration at {r[0]} poses:"
                f" {r[8] / r[6]:.1f}x"
            )
        if np.isfinite(rows[0][9]):
            print(f"iSAM2 time per update, {b[0]} vs {a[0]} poses: {b[9] / a[9]:.2f}x")


if __name__ == "__main__":
    main()
