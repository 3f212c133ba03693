"""How late a log's odometry is against its scans, and the odometry moved back in line with them.

A logger pairs each laser scan with the odometry pose it last received.  Where the two
streams are not in step (the scan time-stamped on arrival, the odometry sampled at another
rate or delayed by its own driver), the pose a scan carries is where the robot was a fraction
of a scan period earlier or later than where the scan was taken.  Over straight driving this
costs little; at every turn the odometry then says the robot turned less (or more) by the
time of the scan than it did, the scan matcher's prior is off by that much, and across a gap in
the log a scan can carry the motion of the gap one scan late.

**The estimate** (:func:`estimate_odometry_delay`).  The scans' own rotation from one scan to
the next is measured by the dense scan matcher (:func:`slam.frontend.scan_match.match_scans`,
the points' Eq. 8 noise, with the odometry's translation as the prior and its rotation left
nearly free, so that the heading change is the points'): ``Δ_k`` from scan ``k − 1`` to scan
``k``.  The odometry's heading ``θ(i)`` is known at each scan index ``i`` and read between
them linearly.  The delay ``λ`` (in scans: the odometry a scan carries is where the robot was
``λ`` scans earlier; negative: later) is the one under which

    Δ_k = θ(k + λ) − θ(k − 1 + λ) + ε_k

fits best, ``ε`` Cauchy-distributed with a scale from the residuals' spread (a wrong match
does not pull the estimate).  It is found on a grid of ``λ`` and refined by a parabola
through the best three points; its standard deviation is from the curvature of the robust
cost there.  Only pairs of scans over which the odometry turned are used (straight driving
says nothing of the delay), and the robot standing still is left out.

**Scans, and the gaps between them** (:func:`scan_slots`).  ``λ`` counts scans, and ``θ`` is
read on an axis on which consecutive scans lie one apart, except across a gap in the log: an
interval between two stamps longer than :data:`GAP_INTERVALS` times the median interval
``Δt̃`` (``interval_s``; at least two scans missing) counts ``Δt / Δt̃``, as long as it lasted.
So a delay of a fraction of a scan reads a fraction of a scan's motion at a gap too, not that
fraction of the whole gap's (ACES turns 1.37 rad over a 3.0 s gap between two laser lines);
a logger late by whole messages is read the same way except at a gap, where the scan before
it is off by at most one scan's motion.  Stamps that go back or stand still anywhere in the
scans read do not measure the time between scans (Intel's go back 631 times; the file order
is the true order): there the axis is the scans' index throughout, gaps included.
``seconds`` is ``λ`` times ``Δt̃``.

**The shift** (:func:`shift_odometry`): each scan's odometry pose (``pose_odom_base`` and
``pose_odom_laser``, each where the scan has one) is replaced by the pose at ``k + λ`` on the
same axis, interpolated between the two scans it falls between (heading along the shorter
arc); before the first scan or after the last the first or last pose is held.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from linefit.config import SensorNoiseConfig
from slam.errors import InputError
from slam.frontend.scan_match import ScanMatchConfig, ScanPoints, match_scans, scan_points
from slam.geometry import pose_between, pose_interpolate
from slam.types import Scan

__all__ = [
    "OdometryDelay",
    "estimate_odometry_delay",
    "median_interval",
    "scan_slots",
    "shift_odometry",
    "slot_step",
]

FloatArray = NDArray[np.float64]

MAX_DELAY_SCANS = 3.0
"""The largest delay (scans, either way) the estimate considers."""

GAP_INTERVALS = 3.0
"""An interval between two scans longer than this many median intervals is a gap in the log
(at least two scans missing), which the delay's axis counts as long as it lasted."""


@dataclass(frozen=True)
class OdometryDelay:
    """An estimate of how many scans late the odometry is.

    Attributes
    ----------
    scans : float
        The delay ``λ`` (scans; positive: the odometry is late).
    sd_scans : float
        Its standard deviation (from the robust cost's curvature).
    seconds : float or None
        ``λ`` times ``interval_s`` (None without it).
    pairs : int
        Pairs of consecutive scans the estimate used (those over which the odometry turned).
    chi2 : float
        The likelihood-ratio statistic of ``λ`` against no delay (χ² with one degree of
        freedom where there is none).
    interval_s : float or None
        The median interval between consecutive scans read (s; None where a stamp goes back,
        stands still or is not finite, :func:`median_interval`): one scan's length on the axis
        ``λ`` is counted on (:func:`scan_slots`).
    """

    scans: float
    sd_scans: float
    seconds: float | None
    pairs: int
    chi2: float
    interval_s: float | None = None

    def to_dict(self) -> dict[str, Any]:
        """The estimate for ``summary.json``."""
        return {
            "scans": self.scans,
            "sd_scans": self.sd_scans,
            "seconds": self.seconds,
            "pairs": self.pairs,
            "chi2_against_none": self.chi2,
            "interval_s": self.interval_s,
        }


def median_interval(timestamps: Iterable[float]) -> float | None:
    """The median interval between consecutive stamps (s), or None where they cannot tell it.

    None where a stamp goes back, stands still or is not finite (the stamps then do not
    measure the time between scans; module docstring), or where there are fewer than two.
    """
    dt = np.diff(np.asarray(list(timestamps), dtype=float))
    if dt.size == 0 or not np.all(np.isfinite(dt)) or np.any(dt <= 0.0):
        return None
    return float(np.median(dt))


def slot_step(dt: float, interval_s: float | None) -> float:
    """How far apart two consecutive scans ``dt`` seconds apart lie on the delay's axis.

    1, except across a gap (``dt`` beyond :data:`GAP_INTERVALS` times ``interval_s``):
    ``dt / interval_s`` (module docstring).  1 without an interval.
    """
    if interval_s is None or not math.isfinite(dt) or dt <= GAP_INTERVALS * interval_s:
        return 1.0
    return dt / interval_s


def scan_slots(timestamps: Iterable[float], interval_s: float | None) -> FloatArray:
    """Each scan's place on the axis the delay is counted on, the first at 0 (module docstring).

    Parameters
    ----------
    timestamps : iterable of float
        The scans' stamps (s), in log order.
    interval_s : float or None
        The median interval (:func:`median_interval`); None gives the scans' indices.

    Returns
    -------
    ndarray, shape (n,)
    """
    t = np.asarray(list(timestamps), dtype=float)
    if t.size == 0:
        return t
    steps = [slot_step(float(d), interval_s) for d in np.diff(t)]
    return np.concatenate([[0.0], np.cumsum(steps)])


def _pose_at(poses: FloatArray, slots: FloatArray, at: float) -> FloatArray:
    """The pose at ``at`` on the axis ``slots`` (increasing) of ``poses`` (held beyond the ends)."""
    n = poses.shape[0]
    if at <= slots[0]:
        return poses[0].copy()
    if at >= slots[n - 1]:
        return poses[n - 1].copy()
    i = int(np.searchsorted(slots, at, side="right")) - 1
    f = (at - slots[i]) / (slots[i + 1] - slots[i])
    if f == 0.0:
        return poses[i].copy()
    return pose_interpolate(poses[i], poses[i + 1], f)


def shift_odometry(
    scans: Iterable[Scan], delay_scans: float, interval_s: float | None = None
) -> Iterator[Scan]:
    """``scans`` with each odometry pose read ``delay_scans`` scans later (module docstring).

    Parameters
    ----------
    scans : iterable of Scan
        In log order.
    delay_scans : float
        ``λ`` (scans; positive: the odometry is late).  0 passes the scans unchanged.
    interval_s : float, optional
        The median interval between the scans (s), which sets how long a gap counts
        (:func:`scan_slots`); None counts every scan as one, gaps included.

    The scans are held back as far as the delay reaches ahead (at most ``ceil(delay_scans)``
    of them: consecutive scans lie at least one apart).
    """
    if not math.isfinite(delay_scans):
        raise InputError(f"the odometry delay must be a finite number of scans, got {delay_scans}")
    if delay_scans == 0.0:
        yield from scans
        return
    ahead = max(math.ceil(delay_scans), 0)
    behind = max(math.ceil(-delay_scans), 0)
    window: deque[tuple[Scan, float]] = deque()  # (scan, slot): scans k − behind .. k + ahead
    first = 0  # the index of window[0]
    k = 0  # the next scan to pass on
    it = iter(scans)
    done = False
    while True:
        while not done and (not window or first + len(window) - 1 < k + ahead):
            try:
                scan = next(it)
            except StopIteration:
                done = True
                break
            slot = 0.0
            if window:
                last, last_slot = window[-1]
                slot = last_slot + slot_step(scan.timestamp - last.timestamp, interval_s)
            window.append((scan, slot))
        if k >= first + len(window):
            return
        yield _shifted(window, first, k, delay_scans)
        k += 1
        while window and first < k - behind:
            window.popleft()
            first += 1


def _shifted(window: deque[tuple[Scan, float]], first: int, k: int, delay: float) -> Scan:
    scan, slot = window[k - first]
    slots = np.array([sl for _, sl in window])
    changes: dict[str, Any] = {}
    for name in ("pose_odom_base", "pose_odom_laser"):
        poses = [getattr(s, name) for s, _ in window]
        if getattr(scan, name) is None or any(p is None for p in poses):
            continue
        changes[name] = _pose_at(np.asarray(poses, dtype=float), slots, slot + delay)
    return replace(scan, **changes) if changes else scan


def estimate_odometry_delay(
    scans: Iterable[Scan],
    noise: SensorNoiseConfig | None = None,
    matching: ScanMatchConfig | None = None,
    *,
    min_turn_rad: float = math.radians(2.0),
    max_pairs: int = 300,
) -> OdometryDelay | None:
    """How many scans late the odometry of ``scans`` is (module docstring).

    Parameters
    ----------
    scans : iterable of Scan
        Consecutive scans with odometry (``pose_odom_laser``), in log order; read until
        ``max_pairs`` turning pairs are matched.
    noise, matching
        The points' noise and the scan matcher's settings (defaults: the paper's, the
        matcher's).
    min_turn_rad : float
        A pair of consecutive scans is used where the odometry turned at least this much
        between them or the next (rad).
    max_pairs : int
        Matched pairs to stop at.

    Returns
    -------
    OdometryDelay or None
        None when fewer than 20 pairs could be used (a log that hardly turns), when the best
        fit lies at the edge of the delays considered (±:data:`MAX_DELAY_SCANS`), or when the
        scans turn against the odometry (a scanner mounted upside down and not stated so).
    """
    noise = noise or SensorNoiseConfig()
    cfg = matching or ScanMatchConfig()
    headings: list[float] = []  # odometry heading of every scan read (unwrapped later)
    times: list[float] = []
    measured: list[tuple[int, float]] = []  # (k, the scans' rotation from k − 1 to k)
    last: tuple[Scan, ScanPoints | None] | None = None
    prev_pose: FloatArray | None = None
    for k, scan in enumerate(scans):
        pose = scan.pose_odom_laser
        if pose is None:
            return None
        pose = np.asarray(pose, dtype=float)
        headings.append(float(pose[2]))
        times.append(float(scan.timestamp))
        points = None
        if prev_pose is not None and last is not None:
            step = pose_between(prev_pose, pose)
            if abs(step[2]) >= min_turn_rad:
                ref = last[1] or scan_points(
                    last[0].ranges, last[0].bearings, last[0].max_range_m, noise, cfg
                )
                points = scan_points(scan.ranges, scan.bearings, scan.max_range_m, noise, cfg)
                # the translation's prior as the odometry's, the rotation nearly free
                sxy = 0.1 + float(np.hypot(step[0], step[1]))
                Q = np.diag([sxy**2, sxy**2, 0.5**2])
                match = match_scans(ref, points, step, Q, cfg)
                if match.accepted:
                    measured.append((k, float(match.delta[2])))
        last = (scan, points)
        prev_pose = pose
        if len(measured) >= max_pairs:
            break
    if len(measured) < 20:
        return None
    theta = np.unwrap(np.asarray(headings))
    interval = median_interval(times)
    slots = scan_slots(times, interval)
    ks = np.array([m[0] for m in measured], dtype=int)
    at, before = slots[ks], slots[ks - 1]
    rot = np.array([m[1] for m in measured])

    def turned(lam: float) -> FloatArray:
        """The odometry's turn from scan ``k − 1`` to scan ``k``, each read ``λ`` later."""
        return np.interp(at + lam, slots, theta) - np.interp(before + lam, slots, theta)

    def residuals(lam: float) -> FloatArray:
        return np.asarray(
            [math.remainder(float(v), 2.0 * math.pi) for v in rot - turned(lam)], dtype=float
        )

    grid = np.arange(-MAX_DELAY_SCANS, MAX_DELAY_SCANS + 1e-9, 0.05)
    # the Cauchy scale from the residuals' spread at the best point of a plain fit
    plain = np.array([np.median(np.abs(residuals(g))) for g in grid])
    scale = max(1.4826 * float(plain.min()), 1e-4)

    def cost(lam: float) -> float:
        r = residuals(lam) / scale
        return float(np.sum(np.log1p(r * r)))

    costs = np.array([cost(g) for g in grid])
    i = int(np.argmin(costs))
    if i == 0 or i == grid.shape[0] - 1:
        return None  # no delay within ±MAX_DELAY_SCANS fits best
    if float(np.sum(rot * turned(float(grid[i])))) <= 0.0:
        return None  # the scans turn against the odometry (a mirrored scanner): no delay fits
    c0, c1, c2 = costs[i - 1], costs[i], costs[i + 1]
    h = grid[1] - grid[0]
    curv = (c0 - 2.0 * c1 + c2) / h**2
    lam = float(grid[i])
    if curv > 0.0:
        lam = float(grid[i] + 0.5 * h * (c0 - c2) / (c0 - 2.0 * c1 + c2))
    # the robust cost is the Cauchy errors' negative log-likelihood (up to a constant)
    sd = math.sqrt(1.0 / curv) if curv > 0.0 else float("inf")
    chi2 = 2.0 * max(cost(0.0) - cost(lam), 0.0)
    seconds = None if interval is None else lam * interval
    return OdometryDelay(lam, sd, seconds, len(measured), chi2, interval)
