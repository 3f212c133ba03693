"""Is a log's odometry biased?  The raw odometry's NEES against the relations, by their length.

For a log with relations: each relation's error of the raw odometry (as the estimators read
it: ``--odometry-sign velocity``, the default), whitened by the covariance a random-walk
motion model gives the chain of odometry steps between its two stamps
(:func:`slam.evaluation.odometry_bias.odometry_relations_nees`), summarised per range of
relation durations; then the same with the odometry calibrated (translation scale, turn gain,
heading drift per metre) by a fit to the relations shorter than ``--short`` seconds only.

The motion model is the one a run estimated for the log (``--noise-from RUN``: the
``odometry_noise`` of its ``summary.json``, without the per-step floors, which count steps
rather than motion) or the default ``[slam.motion]``.  A NEES near 3 at every length: the
random walk describes the odometry; rising with length: a persistent error; falling to about
3 at every length once calibrated on the short relations: that error is a bias of the three
kinds above, visible in a few seconds of data.  ``--mounting`` also fits, alone, where the
laser sits in the frame whose motion the odometry reports (a lever arm moves the laser
sideways on every turn), and adds its column.

    python scripts/odometry_bias.py fr079 --noise-from results/fr079
    python scripts/odometry_bias.py intel --noise-from results/intel --mounting
"""

from __future__ import annotations

import argparse
import json
from dataclasses import fields
from itertools import pairwise
from pathlib import Path

from slam import blas as _blas  # noqa: F401  # isort: skip  (before numpy: slam.blas)
import numpy as np

from slam.errors import EvaluationError
from slam.evaluation.odometry_bias import (
    fit_odometry_calibration,
    odometry_relations_nees,
    relation_pairs,
)
from slam.io.carmen import scan_trajectory
from slam.io.catalog import resolve_log
from slam.io.relations import read_relations
from slam.models.motion import MotionNoiseConfig

BINS_S = (0.0, 10.0, 60.0, 300.0, float("inf"))


def _noise(run: Path | None, floors: bool = False) -> MotionNoiseConfig:
    """The motion model: the default, or the run's fit without (or with) its per-step floors."""
    if run is None:
        return MotionNoiseConfig()
    fitted = json.loads((run / "summary.json").read_text())["odometry_noise"]
    rates = {f.name: float(fitted[f.name]) for f in fields(MotionNoiseConfig) if "_per_" in f.name}
    if floors:
        return MotionNoiseConfig(
            **rates,
            sigma_xy_min_m=float(fitted["sigma_xy_min_m"]),
            sigma_theta_min_rad=float(fitted["sigma_theta_min_rad"]),
        )
    return MotionNoiseConfig(**rates, sigma_xy_min_m=1e-9, sigma_theta_min_rad=1e-9)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("log", help="log file or dataset name (needs its relations)")
    ap.add_argument("--noise-from", type=Path, default=None, help="a run's results folder")
    ap.add_argument("--short", type=float, default=10.0, help="s: relations the fit uses")
    ap.add_argument("--odometry-sign", choices=("velocity", "logged"), default="velocity")
    ap.add_argument(
        "--mounting",
        action="store_true",
        help="also fit where the laser sits in the odometry's frame (a column of its own)",
    )
    args = ap.parse_args()
    log = resolve_log(args.log)
    if log.relations is None:
        raise SystemExit(f"{args.log}: no relations file known for this log")
    frame = log.manifest.relations_frame if log.manifest is not None else "laser"
    odometry = scan_trajectory(log.log, frame=frame, odometry_sign=args.odometry_sign)
    rel = read_relations(log.relations)
    pairs = relation_pairs(odometry.timestamps, rel.t1, rel.t2, rel.poses)
    noise = _noise(args.noise_from)
    short = pairs.duration_s < args.short
    try:
        as_logged = odometry_relations_nees(odometry.poses, pairs, noise)
    except EvaluationError as exc:
        # the run's model leaves some chain no error without its floors (e.g. no translation
        # noise per radian turned, on a turn on the spot)
        if args.noise_from is None:
            raise SystemExit(f"{args.log}: {exc}") from exc
        print(f"# {exc}: the run's per-step floors are kept")
        noise = _noise(args.noise_from, floors=True)
        as_logged = odometry_relations_nees(odometry.poses, pairs, noise)
    calibration = fit_odometry_calibration(odometry.poses, pairs, noise, use=short)
    print(f"# {log.name}: {pairs.first.shape[0]} of {len(rel)} relations matched; {noise}")
    print(
        f"# calibration fitted to the {int(short.sum())} relations shorter than {args.short:g} s: "
        f"scale {calibration.scale:+.4f}, turn gain {calibration.turn_gain:+.4f}, "
        f"heading drift {calibration.heading_drift_rad_per_m:+.5f} rad/m"
    )
    nees = {
        "as logged": as_logged,
        "calibrated": odometry_relations_nees(odometry.poses, pairs, noise, calibration),
    }
    if args.mounting:
        mounting = fit_odometry_calibration(
            odometry.poses, pairs, noise, use=short, parameters="mounting"
        )
        print(
            f"# mounting fitted to the same relations (alone): x {mounting.mount_x_m:+.4f} m, "
            f"y {mounting.mount_y_m:+.4f} m in the frame the odometry reports"
        )
        nees["mounting"] = odometry_relations_nees(odometry.poses, pairs, noise, mounting)
    heads = " | ".join(f"{k}: mean / median" for k in nees)
    print(f"| relations (s) | n | NEES {heads} |")
    print("|---|---|" + "---|" * len(nees))
    for lo, hi in pairwise(BINS_S):
        sel = (pairs.duration_s >= lo) & (pairs.duration_s < hi)
        if not np.any(sel):
            continue
        cells = [f"{v[sel].mean():.2f} / {np.median(v[sel]):.2f}" for v in nees.values()]
        span = f"{lo:g}-{hi:g}" if np.isfinite(hi) else f"≥ {lo:g}"
        print(f"| {span} | {int(sel.sum())} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
