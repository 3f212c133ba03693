"""How far separate passes along the same walls disagree, against the line factors' covariances.

Usage::

    python scripts/pass_consistency.py RESULTS_DIR [RESULTS_DIR ...] [--gap-s 10 30] [--max-pairs N]

For each ``lineslam slam`` results folder (its ``graph.g2o``) and each ``--gap-s``, prints the
landmarks and pairs of passes compared, the median of ``t`` over the pairs divided by χ²₂'s
median (and of its angle part by χ²₁'s), and the fraction of pairs beyond χ²₂'s 95 % quantile
(:mod:`slam.line_slam.passes`), each pair's difference judged against its covariance at the
run's fitted estimate (about 1 where the factors' model holds), on at most ``--max-pairs``
pairs drawn with a fixed seed (default 300, as ``lineslam evaluate``; 0: every pair); then the
error each pass shares as estimated from those pairs (offset mm / angle mrad) and the median
and fraction beyond 95 % with it in the pairs' covariances.  Nothing is written.
"""

from __future__ import annotations

import argparse

from slam.line_slam.passes import pass_consistency_of_results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("results", nargs="+", help="lineslam slam results folders")
    parser.add_argument(
        "--gap-s", type=float, nargs="+", default=[10.0, 30.0], help="pass gaps (s)"
    )
    parser.add_argument("--max-pairs", type=int, default=300, help="0: every pair")
    args = parser.parse_args()
    print(
        "| results | gap (s) | landmarks | pairs | median t / χ²₂ | angle / χ²₁ | beyond 95 % "
        "| pass error (mm / mrad) | with it: median t / χ²₂ | beyond 95 % |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for directory in args.results:
        for gap in args.gap_s:
            r = pass_consistency_of_results(directory, gap, args.max_pairs or None)
            error_mm = 1e3 * r.pass_error_sigma_offset_m
            error_mrad = 1e3 * r.pass_error_sigma_angle_rad
            print(
                f"| {directory} | {gap:g} | {r.landmarks} | {r.pairs} | {r.median_ratio:.2f} | "
                f"{r.median_ratio_angle:.2f} | {r.fraction_beyond_95:.2f} | "
                f"{error_mm:.1f} / {error_mrad:.1f} | {r.median_ratio_with_pass_error:.2f} | "
                f"{r.fraction_beyond_95_with_pass_error:.2f} |"
            )


if __name__ == "__main__":
    main()
