"""How good is the laser odometry of a log, alone?  Its short relative poses against a reference.

Usage::

    python scripts/laser_odometry_check.py intel --reference RUN/trajectory.tum
    python scripts/laser_odometry_check.py aces --reference RUN/trajectory.tum \\
        --set sigma_xy_m=0.03 --set matching.normal_length_m=1.0

The laser odometry (:class:`slam.frontend.laser_odometry.LaserOdometry`, the motion of a log
without odometry) is run over every scan of the log, ignoring the log's odometry, with the
default settings or those given by ``--set`` (``NAME=VALUE`` of
:class:`~slam.frontend.laser_odometry.LaserOdometryConfig`, ``matching.NAME=VALUE`` of its
scan matcher's :class:`~slam.frontend.scan_match.ScanMatchConfig`, ``noise.NAME=VALUE`` of
the points' :class:`~linefit.config.SensorNoiseConfig`).  ``--reference`` is a trajectory of
the same scans in the laser frame (e.g. a default ``lineslam slam`` run of the log with its
odometry, whose ``summary.json`` says ``"frame": "laser"``); scans are paired with it by time
stamp.  Printed for the laser odometry and for the log's own odometry alike: the RMS, 95th
percentile and largest translation error of the relative poses ``k`` scans apart
(``--spans``, default 10 and 50), and the scans where the reference moves more than 4 cm
while the odometry moves less than 30 % of that (``stalls``); with ``--worst K`` the ``K``
stretches of the first span where the laser odometry errs most (scans, time stamp, error and
the reference's motion); then the laser odometry's matched, unmatched and rescued scans and
its process CPU time.  Nothing is written.
"""

from __future__ import annotations

import argparse
import itertools
import time
from dataclasses import fields, replace
from typing import Any

import numpy as np

from linefit.config import SensorNoiseConfig
from slam.evaluation.timestamps import match_timestamps
from slam.frontend.laser_odometry import LaserOdometry, LaserOdometryConfig
from slam.frontend.scan_match import ScanMatchConfig
from slam.geometry import pose_between
from slam.inputs import InputPolicy, read_log_scans
from slam.io.tum import read_tum


def _typed(cls: type, name: str, value: str) -> Any:
    """``value`` converted to the type of the field ``name`` of the dataclass ``cls``."""
    for f in fields(cls):
        if f.name == name:
            kind = type(getattr(cls(), name))
            if kind is bool:
                return value.lower() in ("1", "true", "yes")
            return kind(value)
    raise SystemExit(f"--set: {cls.__name__} has no field {name!r}")


def _settings(
    assignments: list[str],
) -> tuple[LaserOdometryConfig, ScanMatchConfig, SensorNoiseConfig]:
    config, matching, noise = LaserOdometryConfig(), ScanMatchConfig(), SensorNoiseConfig()
    for item in assignments:
        key, sep, value = item.partition("=")
        if not sep:
            raise SystemExit(f"--set {item!r}: expected NAME=VALUE")
        if key.startswith("matching."):
            name = key.removeprefix("matching.")
            matching = replace(matching, **{name: _typed(ScanMatchConfig, name, value)})
        elif key.startswith("noise."):
            name = key.removeprefix("noise.")
            noise = replace(noise, **{name: _typed(SensorNoiseConfig, name, value)})
        else:
            config = replace(config, **{key: _typed(LaserOdometryConfig, key, value)})
    return config, matching, noise


def _window_errors(
    poses: np.ndarray, reference: np.ndarray, paired: np.ndarray, span: int
) -> list[tuple[float, int, int]]:
    """``(error, a, b)``: the translation error of each relative pose ``span`` scans apart."""
    out = []
    for a, b in zip(paired[:-span], paired[span:], strict=True):
        d_ref = pose_between(reference[a], reference[b])
        d_odo = pose_between(poses[a], poses[b])
        out.append((float(np.hypot(*(d_ref[:2] - d_odo[:2]))), int(a), int(b)))
    return out


def _errors(
    poses: np.ndarray, reference: np.ndarray, paired: np.ndarray, span: int
) -> tuple[float, float, float]:
    """RMS, 95th percentile and largest translation error of relative poses ``span`` apart."""
    e = np.array([err for err, _, _ in _window_errors(poses, reference, paired, span)])
    return float(np.sqrt(np.mean(e**2))), float(np.percentile(e, 95)), float(e.max())


def _print_worst(
    poses: np.ndarray,
    reference: np.ndarray,
    paired: np.ndarray,
    span: int,
    k: int,
    scans: list[Any],
) -> None:
    """The ``k`` worst relative poses ``span`` scans apart, one per stretch of ``span`` scans."""
    shown: list[int] = []
    for err, a, b in sorted(_window_errors(poses, reference, paired, span), reverse=True):
        if any(abs(a - s) < span for s in shown):
            continue
        shown.append(a)
        moved = float(np.hypot(*pose_between(reference[a], reference[b])[:2]))
        print(
            f"    scans {a}-{b} (t {scans[a].timestamp:.1f} s): error {err:.3f} m, "
            f"the reference moves {moved:.3f} m"
        )
        if len(shown) >= k:
            break


def _stalls(poses: np.ndarray, reference: np.ndarray, paired: np.ndarray) -> int:
    """Consecutive scans the reference moves > 4 cm between and the odometry < 30 % of that."""
    n = 0
    for a, b in itertools.pairwise(paired):
        if b != a + 1:
            continue
        moved = float(np.hypot(*pose_between(reference[a], reference[b])[:2]))
        if moved > 0.04 and float(np.hypot(*pose_between(poses[a], poses[b])[:2])) < 0.3 * moved:
            n += 1
    return n


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("log", help="CARMEN log or dataset name")
    parser.add_argument("--reference", required=True, help="TUM trajectory (laser frame)")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE")
    parser.add_argument("--spans", type=int, nargs="+", default=[10, 50])
    parser.add_argument(
        "--worst",
        type=int,
        default=0,
        metavar="K",
        help="also print the K stretches of the first span where the laser odometry errs most",
    )
    args = parser.parse_args()
    config, matching, noise = _settings(args.set)
    scans = list(read_log_scans(args.log, InputPolicy()))
    laser = LaserOdometry(config, noise=noise, matching=matching)
    start = time.process_time()
    poses = np.array([laser.add(scan) for scan in scans])
    cpu_s = time.process_time() - start
    logged = np.array(
        [np.full(3, np.nan) if s.pose_odom_laser is None else s.pose_odom_laser for s in scans]
    )
    ref = read_tum(args.reference)
    index, ok = match_timestamps(np.array([s.timestamp for s in scans]), ref.timestamps, 1e-5)
    paired = np.flatnonzero(ok)
    reference = np.full((len(scans), 3), np.nan)
    reference[paired] = ref.poses[index[paired]]
    print(f"{args.log}: {len(scans)} scans, {paired.size} in the reference; settings {args.set}")
    for name, trajectory in (("laser odometry", poses), ("logged odometry", logged)):
        if not np.all(np.isfinite(trajectory[paired])):
            print(f"  {name}: not available")
            continue
        parts = []
        for span in args.spans:
            rms, p95, worst = _errors(trajectory, reference, paired, span)
            parts.append(f"{span} scans: RMS {rms:.4f} p95 {p95:.4f} max {worst:.3f} m")
        stalls = _stalls(trajectory, reference, paired)
        print(f"  {name:16s} " + " | ".join(parts) + f" | stalls {stalls}")
    if args.worst > 0:
        _print_worst(poses, reference, paired, args.spans[0], args.worst, scans)
    print(
        f"  laser odometry: matched {laser.matched}, unmatched {laser.unmatched}, "
        f"rescued {laser.rescued}; {cpu_s:.1f} s of CPU"
    )


if __name__ == "__main__":
    main()
