"""What :meth:`LineSlam.add_scan` reports, and the degradations it warns about.

Graceful degradation (each with a :class:`SlamWarning`, counted in the statistics): a keyframe
without usable lines rests on odometry; a keyframe whose matched lines are all parallel (a
corridor) gets no information along them, which the odometry factor supplies; a keyframe where
nothing matches near the prediction (lost association) starts new landmarks and continues on
odometry.  The odometry chain and the prior on the first pose keep the graph well posed in every
case.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "COUNTERS",
    "MIRRORED_P_VALUE",
    "PARALLEL_TOLERANCE_RAD",
    "WARN_LOST",
    "WARN_NO_LINES",
    "WARN_PARALLEL",
    "ScanReport",
    "SlamWarning",
    "all_parallel",
    "degradation",
    "warn_mirrored",
]

COUNTERS = (
    "points",
    "lines_fit",
    "lines_used",
    "lines_matched",
    "lines_new",
    "lines_ambiguous",
    "lines_rejected",
    "landmarks_merged",
    "merges_undone",
    "tentative_started",
    "tentative_promoted",
    "tentative_expired",
    "registrations_failed",
    "registrations_rejected",
    "relocalisations",
    "relocalisations_used",
    "scan_matches",
    "scan_matches_rejected",
    "scan_match_slips",
    "scan_match_contradictions",
    "scan_match_turns",
    "scan_match_turns_against",
    "scan_matches_between",
    "scan_matches_between_rejected",
    "scan_matches_between_searched",
    "loop_closure_attempts",
    "loop_closure_candidates",
    "loop_closures",
    "loop_closures_undone",
    "loop_closures_dropped",
    "loop_closures_repeated",
    "loop_closures_gated",
    "keyframes_without_lines",
    "keyframes_parallel_lines",
    "keyframes_lost_association",
)
"""The counters of a run, in ``summary.json`` (``docs/real-logs.md`` says what each counts)."""


FloatArray = NDArray[np.float64]

PARALLEL_TOLERANCE_RAD = np.deg2rad(5.0)
"""Matched lines whose normals all lie within this of each other (mod π) count as parallel."""

WARN_NO_LINES = "keyframe without usable lines: its pose rests on odometry alone"
WARN_PARALLEL = (
    "all matched lines are parallel (e.g. a corridor): the position along them rests on odometry"
)
MIRRORED_P_VALUE = 1e-3
"""The sign test's level at which scans that turn against the odometry are reported."""


def warn_mirrored(turns: int, against: int) -> str:
    """The warning for scans whose matches turn against the odometry (``against`` of ``turns``)."""
    return (
        f"the scans turn against the odometry in {against} of {turns} turns: are the beams in "
        "clockwise order (a scanner mounted upside down)? State the geometry with the signs of "
        "the first angle and the step changed (CARMEN's 180 beams from -90 deg at 1 deg, upside "
        "down: --first-angle 90 --step -1). Or the odometry counts its turns clockwise"
    )


WARN_LOST = (
    "no line matched the map near the predicted pose (lost association): "
    "continuing on odometry, new landmarks started"
)


class SlamWarning(UserWarning):
    """The estimate is degraded but the run continues (no lines, parallel lines, lost match)."""


@dataclass(frozen=True)
class ScanReport:
    """What :meth:`LineSlam.add_scan` did with one scan.

    Attributes
    ----------
    scan : int
        Position of the scan in the stream (0-based).
    keyframe : bool
        Whether it became a pose variable.
    pose_index : int
        The pose variable it hangs from.
    lines : int
        Usable lines (keyframes only).
    candidates : int
        Landmarks (graph and tentative) offered to the registration.
    matched : int
        Lines paired with a landmark (graph or tentative).
    new_landmarks : int
        Lines that started a (tentative) landmark.
    ambiguous : int
        Lines dropped as ambiguous.
    merged : int
        Landmark fusions performed after this scan.
    loop_closures : int
        Loop closures accepted after this scan.
    warnings : tuple of str
        Degradations (see the module docstring).
    """

    scan: int
    keyframe: bool
    pose_index: int
    lines: int = 0
    candidates: int = 0
    matched: int = 0
    new_landmarks: int = 0
    ambiguous: int = 0
    merged: int = 0
    loop_closures: int = 0
    warnings: tuple[str, ...] = ()


def all_parallel(alpha: FloatArray) -> bool:
    """Whether all normals ``alpha`` are within :data:`PARALLEL_TOLERANCE_RAD` (mod π)."""
    a = np.asarray(alpha, dtype=float)
    if a.size == 0:
        return False
    d = np.abs(np.sin(a[:, None] - a[None, :]))
    return bool(np.max(d) < np.sin(PARALLEL_TOLERANCE_RAD))


def degradation(
    n_lines: int, first: bool, n_candidates: int, matched_alpha: FloatArray
) -> tuple[str, str] | None:
    """The degradation of a keyframe, if any: ``(counter name, warning message)``.

    Parameters
    ----------
    n_lines
        Usable lines of the keyframe.
    first
        Whether it is the first keyframe (nothing to match yet).
    n_candidates
        Landmarks offered to the registration.
    matched_alpha
        Laser-frame normal angles of the lines that were matched.
    """
    if n_lines == 0:
        return "keyframes_without_lines", WARN_NO_LINES
    if not first and n_candidates and matched_alpha.size == 0:
        return "keyframes_lost_association", WARN_LOST
    if matched_alpha.size >= 1 and all_parallel(matched_alpha):
        return "keyframes_parallel_lines", WARN_PARALLEL
    return None
