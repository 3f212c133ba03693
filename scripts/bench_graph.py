"""Benchmark of the factor-graph back-end on synthetic problems (5 line factors per pose).

Side by side, in one run, at 250, 1000, 3000 and 4000 poses.

What each column times (process CPU time, all threads; the problem is at its solution, as in
the later iterations of a solve).  The batch columns are measured interleaved: each of
``--rounds`` rounds calls every timed function once (A B C … A B C …), each column is the best
round, and each ratio is printed with the range of its per-round values, so that both sides of
a ratio saw the same load:

* ``numpy``: the fast path's linearisation of every line factor in numpy
  (``linearize_line_factors``, robust IRLS weights included), per line factor;
* ``lin/f``: the batch solver's linearisation of the whole graph into its normal equations
  (line factors + odometry factors + prior linearised in numpy, ``H = AᵀA`` and ``Aᵀb``
  assembled; ``BatchSolver._linearize_point``), per factor (line + odometry factors + prior, the
  count used by every ``/f`` column); ``elim``: solving that system (the compiled sparse
  ``LDLᵀ``, numeric factorisation and solve; the structure, COLAMD ordering and symbolic
  analysis, done once per solve, outside the timing); ``iter/f``: the two together, one whole
  Gauss-Newton iteration of the batch solver (``linear_solver = "sparse"``), per factor;
* ``GT it/f``: the same iteration with ``linear_solver = "gtsam"``: the ``JacobianFactor``
  objects built and GTSAM's multifrontal elimination (``GaussianFactorGraph.optimize``, COLAMD
  ordering computed outside the timing); ``GT elim``: that elimination alone;
* ``setup``: what each path does once per solve: the sparse path's structure (pattern, COLAMD
  ordering, symbolic analysis; ``BatchSolver._region``) and, ``GT setup``, GTSAM's COLAMD
  ordering of the linearised graph;
* ``solve``: a whole ``BatchSolver.solve`` from the problem's dead-reckoned start to
  convergence, setup included, ``linear_solver = "sparse"`` against ``"gtsam"`` (ratio printed;
  the same iterations on both sides);
* ``CF GN/f``: the same Gauss-Newton iteration (``NonlinearFactorGraph.linearize`` then
  ``GaussianFactorGraph.optimize``, same ordering method) over ``gtsam.CustomFactor`` line
  factors (a Python callback per factor) with the fast path's objective: the line factors'
  Gaussian noise wrapped in GTSAM's ``noiseModel.Robust`` with the solver's kernel (Cauchy,
  ``k`` from ``SolverConfig``); ``CF lin/f``: its linearisation alone;
* ``iSAM2``: the graph fed pose by pose (one ``Isam2Solver.update`` each: line factors as
  per-keyframe ``LinearContainerFactor`` blocks, the estimate read back); process CPU time per
  update, mean over the last 100 updates; and the solver's own split of an update into
  building the blocks, GTSAM's ``ISAM2.update`` and reading the estimate back (means over all
  updates, wall clock);
* ``native``: the same feed into ``gtsam.ISAM2`` with GTSAM's native factors only, the same
  parameters (thresholds, relinearisation skip, partial check): the odometry and prior as
  ours, each line factor replaced by a ``BearingRangeFactor2D`` (same keys, 2 rows, the same
  robust kernel) on a point landmark; one ``ISAM2.update`` per pose and the new pose's estimate
  read; mean over the last 100 updates.  ``iSAM2 / native`` is the cost of our line factors'
  path against factors GTSAM linearises itself (target ≤ 1.2 at 3,000 poses).  Printed after
  the table: over the last 300 updates, both sides' mean time of the updates that relinearise
  (for ours, with the update after each, which rebuilds the stale blocks) and of the others.

Prints the table and the growth of each per-factor cost from the smallest to the largest size
(target ≤ 1.5 for the fast path's whole iteration, elimination included).

    .venv/bin/python scripts/bench_graph.py [--sizes 250 1000 3000 4000] [--rounds 5]
        [--no-isam2]
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from collections.abc import Callable
from dataclasses import replace
from functools import partial
from pathlib import Path
from typing import Any

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
from slam.graph.linear import keys_of, native_odometry_factors
from slam.graph.sparse import NormalEquations
from slam.graph.synthetic import SyntheticProblem


def best_of(fn: Callable[[], object], repeat: int) -> float:
    """Least process CPU time (s) of ``repeat`` calls of ``fn``."""
    times = []
    for _ in range(repeat):
        t0 = time.process_time()
        fn()
        times.append(time.process_time() - t0)
    return min(times)


def interleaved(fns: dict[str, Callable[[], object]], rounds: int) -> dict[str, list[float]]:
    """Process CPU time (s) of each function, per round; every round calls each one once."""
    times: dict[str, list[float]] = {k: [] for k in fns}
    for _ in range(rounds):
        for k, fn in fns.items():
            t0 = time.process_time()
            fn()
            times[k].append(time.process_time() - t0)
    return times


def ratio(times: dict[str, list[float]], a: str, b: str) -> str:
    """``a / b`` of the best rounds, with the range of the per-round ratios."""
    per = np.asarray(times[a]) / np.asarray(times[b])
    return f"{min(times[a]) / min(times[b]):.2f}x ({per.min():.2f}-{per.max():.2f})"


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


def native_isam2(params: gtsam.ISAM2Params, p: SyntheticProblem, config: SolverConfig) -> Any:
    """A feeder of ``p`` into ``gtsam.ISAM2`` with native factors only (see the docstring).

    Line factors become ``BearingRangeFactor2D``s on point landmarks (a point of each line at
    least as far from all its observers as any within 4 m of the point nearest its first
    observer, so that no range is near zero; measured from the true poses, σ 4 mrad, 1 cm), with
    the solver's robust kernel; landmarks are initialised from their first measurement at the
    dead-reckoned pose.  Returns a function of the pose index that feeds that pose and returns
    the number of variables the update relinearised.
    """
    g = p.graph
    fp, fl = g.factor_pose, g.factor_landmark
    first = np.full(g.n_landmarks, -1)
    first[fl[::-1]] = np.arange(g.n_line_factors)[::-1]  # first factor of each landmark
    truth = p.poses_true
    lm = p.landmarks_true
    obs = truth[fp[first]]
    n = np.column_stack([np.cos(lm[:, 1]), np.sin(lm[:, 1])])
    dist = lm[:, 0] - np.einsum("jd,jd->j", obs[:, :2], n)
    foot = obs[:, :2] + dist[:, None] * n
    # the point of the line farthest from its nearest observer among points within 4 m of the
    # foot: a path that crosses a line would otherwise give ranges near 0 (bearing undefined)
    along = np.linspace(-4.0, 4.0, 17)
    cand = foot[:, None, :] + along[None, :, None] * np.column_stack([-n[:, 1], n[:, 0]])[:, None]
    nearest = np.full((g.n_landmarks, along.size), np.inf)
    np.minimum.at(nearest, fl, np.linalg.norm(cand[fl] - truth[fp, None, :2], axis=-1))
    points = cand[np.arange(g.n_landmarks), np.argmax(nearest, axis=1)]
    rng = np.random.default_rng(7)
    d = points[fl] - truth[fp, :2]
    bearing = np.arctan2(d[:, 1], d[:, 0]) - truth[fp, 2] + rng.normal(0.0, 0.004, fp.shape[0])
    rng_m = np.hypot(d[:, 0], d[:, 1]) + rng.normal(0.0, 0.01, fp.shape[0])
    noise = robust_noise(np.diag([0.004**2, 0.01**2]), config)
    isam = gtsam.ISAM2(params)
    odometry = native_odometry_factors(g, with_prior=False)
    prior = native_odometry_factors(g, g.n_odometry, with_prior=True)
    key_x = keys_of("x", np.arange(g.n_poses))
    key_l = keys_of("l", np.arange(g.n_landmarks))
    seen = np.zeros(g.n_landmarks, dtype=bool)
    by_pose = np.split(np.argsort(fp, kind="stable"), np.cumsum(np.bincount(fp))[:-1])

    def feed(i: int) -> int:
        nfg = gtsam.NonlinearFactorGraph()
        values = gtsam.Values()
        pose = g.poses[i]
        values.insert(key_x[i], gtsam.Pose2(*pose))
        if i == 0:
            nfg.push_back(prior)
        else:
            nfg.add(odometry.at(i - 1))
        for f in by_pose[i].tolist():
            j = int(fl[f])
            if not seen[j]:
                seen[j] = True
                ang = pose[2] + bearing[f]
                values.insert(
                    key_l[j],
                    gtsam.Point2(
                        pose[0] + rng_m[f] * np.cos(ang), pose[1] + rng_m[f] * np.sin(ang)
                    ),
                )
            nfg.add(
                gtsam.BearingRangeFactor2D(
                    key_x[i], key_l[j], gtsam.Rot2(float(bearing[f])), float(rng_m[f]), noise
                )
            )
        result = isam.update(nfg, values)
        isam.calculateEstimatePose2(key_x[i])
        return int(result.getVariablesRelinearized())

    return feed


def isam2_feed(
    p: SyntheticProblem, config: SolverConfig
) -> tuple[float, float, float, float, dict[str, float]]:
    """Per-update CPU time of ours and of native factors (interleaved, pose by pose).

    Means over the last 100 updates (s): ours, native; our build/update split (means over all
    updates, wall-clock, from the solver's statistics); and, over the last 300 updates, the
    mean of the updates that relinearised variables (ours: and the update after each, which
    rebuilds the stale blocks) and of the others ("ordinary"), for both.
    """
    src = p.graph
    g = LineGraph()
    assert src.prior_pose is not None and src.prior_cov is not None
    g.set_prior(src.prior_pose, src.prior_cov)
    solver = Isam2Solver(solver=config)
    native = native_isam2(solver.isam.params(), p, config)
    times, times_native = [], []
    relin, relin_native = [], []
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
        t0 = time.process_time()
        result = solver.update(g)
        t1 = time.process_time()
        relin.append(int(result.getVariablesRelinearized()) > 0)
        relin_native.append(native(i) > 0)
        t2 = time.process_time()
        times.append(t1 - t0)
        times_native.append(t2 - t1)
    st = solver.stats
    ours, nat = np.array(times[-300:]), np.array(times_native[-300:])
    r = np.array(relin)
    r[1:] |= r[:-1].copy()  # the relinearising update and the rebuild after it
    ours_relin = r[-300:]
    nat_relin = np.array(relin_native[-300:])

    def mean(t: np.ndarray, mask: np.ndarray) -> float:
        return float(t[mask].mean()) if mask.any() else float("nan")

    split = {
        "ours ordinary": mean(ours, ~ours_relin),
        "ours relinearising": mean(ours, ours_relin),
        "native ordinary": mean(nat, ~nat_relin),
        "native relinearising": mean(nat, nat_relin),
        # our update's three parts, means over all updates (wall clock, the solver's own
        # statistics): building the new and stale blocks in Python, GTSAM's ISAM2.update, and
        # reading the estimate back (GTSAM's back-substitution on the first read included)
        "ours build": st.time_s["build"] / st.updates,
        "ours update": st.time_s["update"] / st.updates,
        "ours read-back": st.time_s["readback"] / st.updates,
    }
    return (
        float(np.mean(times[-100:])),
        float(np.mean(times_native[-100:])),
        st.time_s["build"] / st.updates,
        st.time_s["update"] / st.updates,
        split,
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


def sparse_step(solver: BatchSolver, g: LineGraph, system: NormalEquations, parts: Any) -> Any:
    """One Gauss-Newton iteration of the sparse path: assemble ``H``, ``g``; factorise; solve."""
    system.assemble(solver._linearize_point(g, g.poses, g.landmarks, parts)[0])
    return system.solve()


def full_solve(g: LineGraph, start: tuple[np.ndarray, np.ndarray], config: SolverConfig) -> None:
    """A whole batch solve of ``g`` from the estimate ``start`` (poses, landmarks)."""
    g.poses[:] = start[0]
    g.landmarks[:] = start[1]
    BatchSolver(config).solve(g)


def assemble(solver: BatchSolver, g: LineGraph, system: NormalEquations, parts: Any) -> None:
    """The linearisation of one iteration: every factor in numpy, then ``H`` and ``g``."""
    system.assemble(solver._linearize_point(g, g.poses, g.landmarks, parts)[0])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[250, 1000, 3000, 4000])
    parser.add_argument("--rounds", type=int, default=5, help="interleaved rounds (default 5)")
    parser.add_argument("--no-isam2", action="store_true")
    args = parser.parse_args()
    print(
        f"machine: {cpu_model()}; load average {os.getloadavg()[0]:.2f} at start;"
        f" {args.rounds} interleaved rounds, process CPU time",
        flush=True,
    )
    rows = []
    splits: dict[int, dict[str, float]] = {}
    # what the recorded figures used: COLAMD, whole solves to the relative tolerance alone
    config = SolverConfig(ordering="colamd", absolute_tolerance=0.0)
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
                config.robust_kernel,
                config.robust_k,
            )

        t_np = best_of(fast_numpy, 5) / F
        n_factors = F + g.n_odometry + 1  # line factors, odometry, prior
        lms = solver.active_landmarks(g)
        system, parts = solver._region(g, 0, lms, None)
        assemble(solver, g, system, parts)
        gfg = solver.linearize(g)
        ordering = solver._ordering(gfg)
        nfg, values = custom_graph(g, config)
        cf_ordering = gtsam.Ordering.ColamdGaussianFactorGraph(nfg.linearize(values))
        dr = synthetic_problem(n, lines_per_pose=5, seed=1).graph  # dead-reckoned
        start = (dr.poses.copy(), dr.landmarks.copy())
        times = interleaved(
            {
                "solve": partial(full_solve, dr, start, replace(config, linear_solver="sparse")),
                "GT solve": partial(full_solve, dr, start, replace(config, linear_solver="gtsam")),
                "setup": partial(solver._region, g, 0, lms, None),
                "GT setup": partial(solver._ordering, gfg),
                "lin": partial(assemble, solver, g, system, parts),
                "elim": system.solve,
                "GT elim": partial(gfg.optimize, ordering),
                "iter": partial(sparse_step, solver, g, system, parts),
                "GT iter": partial(gauss_newton_step, partial(solver.linearize, g), ordering),
                "CF lin": partial(nfg.linearize, values),
                "CF GN": partial(gauss_newton_step, partial(nfg.linearize, values), cf_ordering),
            },
            args.rounds,
        )
        best = {k: min(v) for k, v in times.items()}
        t_isam: tuple[float, ...] = (float("nan"),) * 4
        if not args.no_isam2:
            *means, splits[n] = isam2_feed(synthetic_problem(n, lines_per_pose=5, seed=1), config)
            t_isam = tuple(means)
        rows.append(
            (
                n,
                F,
                t_np,
                best["lin"] / n_factors,
                best["elim"],
                best["iter"] / n_factors,
                best["GT iter"] / n_factors,
                best["CF lin"] / nfg.size(),
                best["CF GN"] / nfg.size(),
                *t_isam,
                system.nnz_factor,
                best["GT elim"],
                best["setup"],
                best["GT setup"],
                times,
            )
        )
        print(f"done {n} poses (load average {os.getloadavg()[0]:.2f})", flush=True)

    print()
    print(
        f"{'poses':>6} {'line f.':>8} | {'numpy':>7} {'lin/f':>7} {'elim':>7} {'GT elim':>7}"
        f" {'setup':>7} {'GT set.':>7} {'iter/f':>7} {'GT it/f':>7} | {'CF lin/f':>8}"
        f" {'CF GN/f':>8} | {'iSAM2':>7} {'native':>7} {'ratio':>6} {'build':>7} {'update':>7}"
    )
    print(
        f"{'':>6} {'':>8} | {'µs/f':>7} {'µs/f':>7} {'ms':>7} {'ms':>7} {'ms':>7} {'ms':>7}"
        f" {'µs/f':>7} {'µs/f':>7} | {'µs/f':>8} {'µs/f':>8} | {'ms/upd':>7} {'ms/upd':>7}"
        f" {'':>6} {'ms':>7} {'ms':>7}"
    )
    for r in rows:
        n, F, t_np, t_li, t_el, t_it, t_gt, t_cfl, t_cfi, t_up, t_nat, t_b, t_u = r[:13]
        t_gel, t_set, t_gset = r[14:17]
        print(
            f"{n:>6} {F:>8} | {1e6 * t_np:7.2f} {1e6 * t_li:7.2f} {1e3 * t_el:7.2f}"
            f" {1e3 * t_gel:7.2f} {1e3 * t_set:7.2f} {1e3 * t_gset:7.2f}"
            f" {1e6 * t_it:7.2f} {1e6 * t_gt:7.2f} | {1e6 * t_cfl:8.1f} {1e6 * t_cfi:8.1f} |"
            f" {1e3 * t_up:7.2f} {1e3 * t_nat:7.2f} {t_up / t_nat:6.2f} {1e3 * t_b:7.2f}"
            f" {1e3 * t_u:7.2f}"
        )
    for r in rows:
        print(f"entries of L at {r[0]} poses: {r[13]} ({r[13] / (r[1] + r[0]):.1f} per factor)")
    if len(rows) > 1:
        a, b = rows[0], rows[-1]
        print()
        print(
            f"whole batch Gauss-Newton iteration per factor (linearise + eliminate), {b[0]} vs"
            f" {a[0]} poses: {b[5] / a[5]:.2f}x (target <= 1.5)"
        )
        print(
            f"the same with GTSAM's elimination (linear_solver = gtsam), {b[0]} vs {a[0]} poses:"
            f" {b[6] / a[6]:.2f}x"
        )
    print()
    print("ratios of the best rounds (range of the per-round ratios), interleaved in this run:")
    for r in rows:
        t = r[17]
        print(f"at {r[0]} poses:")
        print(
            f"  whole solve from dead reckoning, GTSAM / sparse: {ratio(t, 'GT solve', 'solve')}"
            f" (sparse {1e3 * min(t['solve']):.0f} ms, GTSAM {1e3 * min(t['GT solve']):.0f} ms)"
        )
        print(f"  one Gauss-Newton iteration, GTSAM / sparse: {ratio(t, 'GT iter', 'iter')}")
        print(f"  the elimination alone, GTSAM / sparse: {ratio(t, 'GT elim', 'elim')}")
        print(f"  once per solve, sparse setup / GTSAM ordering: {ratio(t, 'setup', 'GT setup')}")
        print(f"  CustomFactor iteration / sparse iteration: {ratio(t, 'CF GN', 'iter')}")
    if len(rows) > 1 and np.isfinite(rows[0][9]):
        a, b = rows[0], rows[-1]
        print(f"iSAM2 time per update, {b[0]} vs {a[0]} poses: {b[9] / a[9]:.2f}x")
        for r in rows:
            print(
                f"iSAM2 per update at {r[0]} poses: ours {1e3 * r[9]:.2f} ms, native"
                f" {1e3 * r[10]:.2f} ms: {r[9] / r[10]:.2f}x (target <= 1.2 at 3,000)"
            )
        for n, sp in splits.items():
            print(
                f"iSAM2 at {n} poses, last 300 updates: ordinary ours"
                f" {1e3 * sp['ours ordinary']:.2f} / native {1e3 * sp['native ordinary']:.2f} ms;"
                f" relinearising (ours: and the rebuild after it) ours"
                f" {1e3 * sp['ours relinearising']:.2f} / native"
                f" {1e3 * sp['native relinearising']:.2f} ms"
            )
            print(
                f"our update at {n} poses, means over all updates (wall clock): building the"
                f" blocks {1e3 * sp['ours build']:.2f} ms, ISAM2.update"
                f" {1e3 * sp['ours update']:.2f} ms, reading the estimate back"
                f" {1e3 * sp['ours read-back']:.2f} ms"
            )


if __name__ == "__main__":
    main()
