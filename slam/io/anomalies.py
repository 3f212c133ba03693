"""Log anomalies: things a log reader accepts but a user should hear about.

A reader (:class:`slam.io.carmen.CarmenReader`) reports each anomaly to a
:class:`LogAnomalies`, which counts them per kind, keeps the first occurrence of each, and
with ``strict=True`` raises :class:`~slam.errors.LogFormatError` (file and line named) at the
first one instead.  The runners write the counts into ``summary.json`` (``"log_anomalies"``)
and the command line prints one warning line per kind that occurred
(:meth:`LogAnomalies.messages`); ``--strict`` makes them errors.

Kinds
-----
``time_backwards``
    A laser scan's time stamp is more than :data:`TIME_BACKWARD_TOLERANCE_S` earlier than the
    previous scan's (e.g. two logs joined end to end, or a time stamp cut short).  Smaller
    backward steps are legitimate in some logs and not counted: Intel's stamps go back 631
    times by up to 0.9 s while the file order is the true order.
``repeated_stamps``
    A laser scan has the same time stamp as the scan before (e.g. all stamps zero): the
    evaluation cannot tell such scans apart.
``odometry_jumps``
    The odometry moved between two consecutive laser scans further than the time between
    them allows: more than ``MAX_SPEED_M_S · Δt + JUMP_SLACK_M`` in position or
    ``MAX_TURN_RATE_RAD_S · Δt + JUMP_SLACK_RAD`` in heading (``Δt`` clamped at 0 when time
    goes backwards).  The slack covers time-stamp jitter (Intel: 9 cm and 0.17 rad between
    scans stamped 1 ms apart; ACES: 1.06 rad in 0.16 s once).  None of the catalogued logs
    (Intel, ACES, fr079) has such a jump; a log joined from two has one at the join.
``truncated_lines``
    The last line of the file has no newline and cannot be read, has fewer fields than the
    line of the same type before it, or ends in its ``ipc_timestamp`` written with fewer
    decimals than that line's (a log cut while it was written, e.g. inside the time stamp):
    the line is skipped.
``unknown_messages``
    Lines of message types that neither this reader nor CARMEN knows (skipped).  Types CARMEN
    writes but lineslam does not use (``PARAM``, ``SYNC``, ``TRUEPOS``, ...,
    :data:`CARMEN_MESSAGES`) are skipped without a warning.
``junk_lines``
    Lines that are not CARMEN messages at all (the first word is not a message name, e.g.
    binary garbage or text pasted into the log): skipped.
``fov_mismatch``
    A ``ROBOTLASER1``/``RAWLASER`` line states a field of view more than one beam away from
    both ``(n − 1)`` and ``n`` times its angular resolution (e.g. a driver that caps the beam
    count but writes the configured field of view): its bearings are taken from its start
    angle and resolution, the ``fov`` field is not used.
``malformed_lines``
    Lines that cannot be read, skipped because the reader is lenient (else they are errors).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slam.errors import LogFormatError

__all__ = [
    "ANOMALY_KINDS",
    "CARMEN_MESSAGES",
    "JUMP_SLACK_M",
    "JUMP_SLACK_RAD",
    "MAX_SPEED_M_S",
    "MAX_TURN_RATE_RAD_S",
    "TIME_BACKWARD_TOLERANCE_S",
    "LogAnomalies",
    "is_message_name",
    "readable",
]

TIME_BACKWARD_TOLERANCE_S = 2.0
"""Largest backward step (s) of laser time stamps that is not an anomaly (Intel: 0.9 s)."""

MAX_SPEED_M_S = 2.0
"""Fastest a robot is taken to move (m/s), for odometry jumps."""

MAX_TURN_RATE_RAD_S = 2.0 * math.pi
"""Fastest a robot is taken to turn (rad/s), for odometry jumps."""

JUMP_SLACK_M = 0.5
"""Position change (m) allowed on top of ``MAX_SPEED_M_S · Δt`` (time-stamp jitter)."""

JUMP_SLACK_RAD = 0.5
"""Heading change (rad) allowed on top of ``MAX_TURN_RATE_RAD_S · Δt``."""

ANOMALY_KINDS = (
    "time_backwards",
    "repeated_stamps",
    "odometry_jumps",
    "truncated_lines",
    "unknown_messages",
    "junk_lines",
    "fov_mismatch",
    "malformed_lines",
)

CARMEN_MESSAGES = frozenset(
    {
        "PARAM",
        "SYNC",
        "TRUEPOS",
        "ROBOTLASER2",
        "LASER3",
        "LASER4",
        "POSITIONLASER",
        "NMEAGGA",
        "NMEARMC",
        "GPSNMEA",
        "SONAR",
        "BUMPER",
        "SCANMARK",
        "IMU",
        "VECTORMOVE",
        "ROBOTVELOCITY",
        "FOLLOW-TRAJECTORY",
        "BASEVELOCITY",
        "ARM",
        "PANTILT",
        "SIMULATOR",
        "MARKER",
        "VERSION",
        "LOGGER",
    }
)
"""Message types CARMEN writes that lineslam does not read: skipped without a warning."""

_NAME = re.compile(r"[A-Z][A-Z0-9_\-]{0,39}")

_SHORT = {
    "time_backwards": "time goes backwards",
    "repeated_stamps": "repeated time stamp",
    "odometry_jumps": "odometry jump",
    "truncated_lines": "last line cut short",
    "unknown_messages": "unknown message type",
    "junk_lines": "not a CARMEN message",
    "fov_mismatch": "field of view not the beams' sweep",
    "malformed_lines": "malformed line",
}
"""What an anomaly is, in the error of a strict reader (``file:line: SHORT: detail``)."""

_TEXT = {
    "time_backwards": "backward time step(s) of more than {tol:g} s between laser scans",
    "repeated_stamps": "laser scan(s) stamped the same as the scan before",
    "odometry_jumps": "odometry jump(s) too large for the time step (limits {v:g} m/s, "
    "{w:.3g} rad/s, + {sm:g} m, {sr:g} rad)",
    "truncated_lines": "last line cut short, skipped",
    "unknown_messages": "line(s) of unknown message types skipped",
    "junk_lines": "line(s) that are not CARMEN messages skipped",
    "fov_mismatch": "laser line(s) whose fov field is not their beams' sweep (fov not used)",
    "malformed_lines": "malformed line(s) skipped (lenient reading)",
}
"""What a count of anomalies is, in the warning lines (``file: N TEXT; first at line L``)."""


def is_message_name(token: str) -> bool:
    """``token`` looks like a CARMEN message name (upper case, digits, ``_`` or ``-``)."""
    return _NAME.fullmatch(token) is not None


def readable(value: float) -> str:
    """``value`` with three decimals, or in exponent notation when it is huge (a corrupt pose)."""
    return f"{value:.3f}" if abs(value) < 1e9 else f"{value:.3g}"


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


@dataclass
class LogAnomalies:
    """Counts of the anomalies of one pass over a log (module docstring).

    Attributes
    ----------
    path : str
        The log.
    strict : bool
        Raise :class:`LogFormatError` at the first anomaly instead of counting it.
    counts : dict
        Per kind (:data:`ANOMALY_KINDS`), how many.
    first : dict
        Per kind that occurred, ``(line_number, detail)`` of the first occurrence.
    unknown_types : dict
        Unknown message types and how many lines of each.
    """

    path: str = ""
    strict: bool = False
    counts: dict[str, int] = field(default_factory=lambda: dict.fromkeys(ANOMALY_KINDS, 0))
    first: dict[str, tuple[int, str]] = field(default_factory=dict)
    unknown_types: dict[str, int] = field(default_factory=dict)
    _last_time: float | None = None
    _last_pose: NDArray[np.float64] | None = None

    def reset(self, path: str) -> None:
        """Zero the counts (a new pass over ``path`` starts); ``strict`` is kept."""
        self.path = path
        self.counts = dict.fromkeys(ANOMALY_KINDS, 0)
        self.first = {}
        self.unknown_types = {}
        self._last_time = None
        self._last_pose = None

    @property
    def total(self) -> int:
        """Number of anomalies of every kind."""
        return sum(self.counts.values())

    def add(self, kind: str, line_number: int, detail: str) -> None:
        """Count one anomaly (or raise, when strict)."""
        if self.strict:
            raise LogFormatError(f"{_SHORT[kind]}: {detail} (--strict)", self.path, line_number)
        self.counts[kind] += 1
        self.first.setdefault(kind, (line_number, detail))

    def unknown(self, kind: str, line_number: int, line: str) -> None:
        """A line whose message type is not read: unknown, junk, or a CARMEN type (ignored)."""
        if is_message_name(kind):
            if kind in CARMEN_MESSAGES:
                return
            self.add("unknown_messages", line_number, kind)
            self.unknown_types[kind] = self.unknown_types.get(kind, 0) + 1
            return
        text = line.strip()
        shown = text[:40] + ("..." if len(text) > 40 else "")
        self.add("junk_lines", line_number, f"{shown!r} ({len(text)} characters)")

    def scan(self, timestamp: float, pose: NDArray[np.float64] | None, line_number: int) -> None:
        """Check a laser scan's time stamp and odometry against the scan before."""
        last_t, last_pose = self._last_time, self._last_pose
        self._last_time = timestamp
        if pose is not None:
            self._last_pose = pose
        if last_t is None:
            return
        dt = timestamp - last_t
        if dt < -TIME_BACKWARD_TOLERANCE_S:
            self.add(
                "time_backwards",
                line_number,
                f"{-dt:.3f} s back ({last_t:.6f} -> {timestamp:.6f}), more than the "
                f"{TIME_BACKWARD_TOLERANCE_S:g} s tolerated",
            )
        elif dt == 0.0:
            self.add(
                "repeated_stamps",
                line_number,
                f"{timestamp:.6f}, as the scan before",
            )
        if pose is None or last_pose is None:
            return
        span = max(dt, 0.0)
        moved = math.hypot(float(pose[0] - last_pose[0]), float(pose[1] - last_pose[1]))
        turned = abs(_wrap(float(pose[2] - last_pose[2])))
        if moved > MAX_SPEED_M_S * span + JUMP_SLACK_M or (
            turned > MAX_TURN_RATE_RAD_S * span + JUMP_SLACK_RAD
        ):
            self.add(
                "odometry_jumps",
                line_number,
                f"{readable(moved)} m and {turned:.3f} rad in {dt:.3f} s",
            )

    def to_dict(self) -> dict[str, Any]:
        """``summary.json``'s ``"log_anomalies"``: per kind ``{"count"}`` (+ first line)."""
        out: dict[str, Any] = {}
        for kind in ANOMALY_KINDS:
            entry: dict[str, Any] = {"count": self.counts[kind]}
            if kind in self.first:
                entry["first_line"], entry["first"] = self.first[kind]
            if kind == "unknown_messages" and self.unknown_types:
                entry["types"] = dict(self.unknown_types)
            out[kind] = entry
        return out

    def messages(self) -> list[str]:
        """One line per kind that occurred: count, what, and where it first happened."""
        return anomaly_messages(self.path, self.to_dict())


def anomaly_messages(path: str, anomalies: dict[str, Any]) -> list[str]:
    """The warning lines of a ``"log_anomalies"`` dict (:meth:`LogAnomalies.to_dict`)."""
    lines = []
    for kind in ANOMALY_KINDS:
        entry = anomalies.get(kind) or {}
        n = int(entry.get("count", 0))
        if n == 0:
            continue
        what = _TEXT[kind].format(
            tol=TIME_BACKWARD_TOLERANCE_S,
            v=MAX_SPEED_M_S,
            w=MAX_TURN_RATE_RAD_S,
            sm=JUMP_SLACK_M,
            sr=JUMP_SLACK_RAD,
        )
        text = f"{path}: {n} {what}"
        if kind == "unknown_messages" and entry.get("types"):
            text += " (" + ", ".join(f"{k}: {v}" for k, v in entry["types"].items()) + ")"
        if "first_line" in entry:
            text += f"; first at line {entry['first_line']}: {entry['first']}"
        lines.append(text)
    return lines
