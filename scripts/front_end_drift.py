"""How far does the front end drift between loop closures?  Loop closing off vs a reference.

For each log: ``lineslam slam`` with the default configuration (the reference trajectory,
loop closing on) and with ``[slam.loop_closure] enabled = false`` (the front end alone:
scan matching, registration, relocalisation, fusion), then the translation error of the
relative pose over every stretch of W metres of path (:func:`slam.evaluation.rpe_errors`, all
pairs: overlapping windows), as the median, 99th percentile and largest value.  The
loop-closure search window (``LoopClosureConfig.window_sigmas`` standard deviations of the
drift that :mod:`slam.line_slam.drift` predicts) should cover the drift a loop can have
accumulated, and not much more: a wider window admits aliases in repeating buildings.

    LINESLAM_DATA=/path/to/shared/datasets .venv/bin/python scripts/front_end_drift.py
    .venv/bin/python scripts/front_end_drift.py --logs fr079 --windows 10 50 100

The reference is the default run, not ground truth: its own error (a few centimetres on
these logs, README) is part of the numbers.
"""

from __future__ import annotations

import argparse
import tempfile
from dataclasses import replace
from pathlib import Path

from slam import blas as _blas  # noqa: F401  # isort: skip  (before numpy: slam.blas)
import numpy as np

from slam.config import RunConfig
from slam.evaluation import rpe_errors
from slam.io.catalog import load_catalog
from slam.io.tum import read_tum
from slam.runner import run_slam


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--logs", nargs="+", default=None, help="default: every catalogued log")
    parser.add_argument(
        "--windows", nargs="+", type=float, default=[10.0, 25.0, 50.0, 100.0, 200.0]
    )
    args = parser.parse_args()
    names = args.logs or [n for n, d in load_catalog().items() if d.relations]
    default = RunConfig()
    no_closing = replace(
        default,
        slam=replace(default.slam, loop_closure=replace(default.slam.loop_closure, enabled=False)),
    )
    print("| log | W (m) | pairs | median (m) | p99 (m) | max (m) | p99 per m |")
    print("|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            ref_dir, est_dir = Path(tmp) / f"{name}-ref", Path(tmp) / f"{name}-front-end"
            run_slam(name, ref_dir, default)
            run_slam(name, est_dir, no_closing)
            ref = read_tum(ref_dir / "trajectory.tum")
            est = read_tum(est_dir / "trajectory.tum")
            for w in args.windows:
                e = rpe_errors(est, ref, w, all_pairs=True)
                t = np.hypot(e[:, 0], e[:, 1])
                p99 = float(np.percentile(t, 99))
                print(
                    f"| {name} | {w:.0f} | {t.size} | {np.median(t):.2f} | {p99:.2f}"
                    f" | {t.max():.2f} | {p99 / w:.4f} |",
                    flush=True,
                )


if __name__ == "__main__":
    main()
