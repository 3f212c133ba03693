"""Monte-Carlo consistency table of the line and endpoint covariances (for docs/linefit.md).

Usage::

    python scripts/report_linefit_mc.py [--trials 4000] [--seed 2003]

Same cases and estimator as ``tests/test_covariance.py`` (it imports that test's helpers).
Prints a markdown table: empirical/predicted variance of R, α, S, mean NEES of (R, α) (χ²₂,
expected 2) and of each endpoint (χ²₁, expected 1), and the ratio of the empirical endpoint
variance to the paper's P_S of the extreme point (Eq. 15), for both bearing-error models.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from _mc import fit_trials, mean_nees, nees_bounds
from _synthetic import wall_scan
from test_covariance import CASES

from linefit import LineFitConfig, SensorNoiseConfig


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=4000)
    ap.add_argument("--seed", type=int, default=2003)
    args = ap.parse_args()
    lo2, hi2 = nees_bounds(2, args.trials)
    lo1, hi1 = nees_bounds(1, args.trials)
    print(
        f"{args.trials} trials per case, seed {args.seed}; 99 % NEES intervals: "
        f"χ²₂ mean [{lo2:.3f}, {hi2:.3f}], χ²₁ mean [{lo1:.3f}, {hi1:.3f}]\n"
    )
    print("| model | case | var R | var α | var S | NEES (R,α) | NEES ends | ends / paper P_S |")
    print("|---|---|---|---|---|---|---|---|")
    for model in ("beam", "reading"):
        cfg = LineFitConfig(noise=SensorNoiseConfig(bearing_error=model))
        for name, (r, alpha, t0, t1, n) in CASES.items():
            s = r * np.tan(np.radians(np.linspace(t0, t1, n)))
            obs = wall_scan(r, alpha, s, args.trials, np.random.default_rng(args.seed), model=model)
            tr = fit_trials(obs, r, alpha, cfg)
            ratio = tr.errors.var(axis=0) / np.diag(tr.cov.cov.mean(axis=0))
            nees2 = mean_nees(tr.errors[:, :2], tr.cov.cov[:, :2, :2])
            nees_end = np.mean(tr.end_errors**2 / tr.end_var, axis=0)
            p_s = tr.fit.p_s.reshape(tr.n_trials, tr.n_points)[:, [0, -1]].mean(axis=0)
            paper = tr.end_errors.var(axis=0) / p_s
            print(
                f"| {model} | {name} | {ratio[0]:.3f} | {ratio[1]:.3f} | {ratio[2]:.3f} | "
                f"{nees2:.3f} | {nees_end[0]:.3f} / {nees_end[1]:.3f} | "
                f"{paper[0]:.2f} / {paper[1]:.2f} |"
            )


if __name__ == "__main__":
    main()
