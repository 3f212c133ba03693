"""Benchmark of the factor-graph back-end on synthetic problems (5 line factors per pose).

Side by side, in one run, at 250, 1000 and 4000 poses:

* **fast path**: one linearisation of every line factor in numpy (``linearize_line_factors``)
  plus the ``gtsam.JacobianFactor`` objects, per line factor; then the whole batch iteration
  (odometry + line factors linearised, GTSAM elimination), per factor;
* **CustomFactor path**: ``NonlinearFactorGraph.linearize`` over ``gtsam.CustomFactor`` line
  factors (Python callback per factor) and, at 250 and 1000 poses, one iteration of GTSAM's own
  Levenberg-Marquardt; at 4000 poses only the linearisation (the LM iteration is the slow case);
* **iSAM2**: the graph fed pose by pose (one ``ISAM2.update`` each, line factors as
  per-keyframe ``LinearContainerFactor`` blocks); time per update over the last 100 updates.

Prints a table and the ratio of the 4000-pose to the 250-pose cost per factor (target ≤ 1.5
for the fast path).

    .venv/bin/python scripts/bench_graph.py [--sizes 250 1000 4000] [--no-isam2]
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from functools import partial

import gtsam
import numpy as np

from slam.geometry import line_to_parent, pose_compose
from slam.graph import BatchSolver, Isam2Solver, LineGraph, line_custom_factor, synthetic_problem
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
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def custom_graph(g: LineGraph) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values]:
    nfg = native_odometry_factors(g)
    kx = keys_of("x", g.factor_pose)
    kl = keys_of("l", g.factor_landmark)
    for f in range(g.n_line_factors):
        nfg.add(
            line_custom_factor(
                kx[f], kl[f], g.anchors[g.factor_landmark[f]], g.factor_z[f], g.factor_cov[f]
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[250, 1000, 4000])
    parser.add_argument("--no-isam2", action="store_true")
    args = parser.parse_args()
    rows = []
    for n in args.sizes:
        p = synthetic_problem(n, lines_per_pose=5, seed=1)
        g = p.graph
        solver = BatchSolver()
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
        t_lin = best_of(partial(solver.linearize, g), 3)
        gfg = solver.linearize(g)
        ordering = gtsam.Ordering.ColamdGaussianFactorGraph(gfg)
        t_elim = best_of(partial(gfg.optimize, ordering), 3)
        n_factors = F + g.n_odometry + 1
        nfg, values = custom_graph(g)
        t_cf_lin = best_of(partial(nfg.linearize, values), 1 if n >= 4000 else 2) / nfg.size()
        t_cf_lm = float("nan")
        if n < 4000:
            opt = gtsam.LevenbergMarquardtOptimizer(nfg, values, gtsam.LevenbergMarquardtParams())
            t0 = time.perf_counter()
            opt.iterate()
            t_cf_lm = (time.perf_counter() - t0) / nfg.size()
        t_isam = (float("nan"),) * 3
        if not args.no_isam2:
            t_isam = isam2_feed(synthetic_problem(n, lines_per_pose=5, seed=1).graph)
        rows.append(
            (n, F, t_np, t_jf, t_lin / n_factors, t_elim, t_cf_lin, t_cf_lm, *t_isam, t_jf1)
        )
        print(f"done {n} poses", flush=True)

    print()
    print(
        f"{'poses':>6} {'line f.':>8} | {'numpy':>7} {'+JacF':>7} {'iter/f':>7} {'elim':>7} |"
        f" {'CF lin':>7} {'CF LM':>8} | {'iSAM2/upd':>9} {'build':>7} {'update':>7}"
    )
    print(
        f"{'':>6} {'':>8} | {'µs/f':>7} {'µs/f':>7} {'µs/f':>7} {'ms':>7} |"
        f" {'µs/f':>7} {'µs/f':>8} | {'ms':>9} {'ms':>7} {'ms':>7}"
    )
    for n, F, t_np, t_jf, t_it, t_el, t_cfl, t_cflm, t_up, t_b, t_u, _ in rows:
        print(
            f"{n:>6} {F:>8} | {1e6 * t_np:7.2f} {1e6 * t_jf:7.2f} {1e6 * t_it:7.2f}"
            f" {1e3 * t_el:7.1f} | {1e6 * t_cfl:7.1f} {1e6 * t_cflm:8.1f} |"
            f" {1e3 * t_up:9.2f} {1e3 * t_b:7.2f} {1e3 * t_u:7.2f}"
        )
    if len(rows) > 1:
        a, b = rows[0], rows[-1]
        fast_a, fast_b = a[2] + a[3], b[2] + b[3]
        print()
        print(
            f"fast path (numpy + JacobianFactor) per line factor, {b[0]} vs {a[0]} poses: "
            f"{fast_b / fast_a:.2f}x (target <= 1.5)"
        )
        print(f"whole batch iteration per factor, {b[0]} vs {a[0]} poses: {b[4] / a[4]:.2f}x")
        for r in rows:
            print(
                f"JacobianFactors per line factor at {r[0]} poses: packed {1e6 * r[3]:.2f} µs,"
                f" one each {1e6 * r[11]:.2f} µs ({r[11] / r[3]:.2f}x)"
            )
        print(f"CustomFactor linearize per factor, {b[0]} vs {a[0]} poses: {b[6] / a[6]:.2f}x")
        print(
            f"CustomFactor linearize / fast path per factor at {b[0]} poses: {b[6] / fast_b:.1f}x"
        )
        if np.isfinite(rows[0][8]):
            print(f"iSAM2 time per update, {b[0]} vs {a[0]} poses: {b[8] / a[8]:.2f}x")


if __name__ == "__main__":
    main()
