"""Variants of the catalogued logs that the system was never tuned on, and how a run is scored.

Main entry points::

    VARIANTS                                   # the table: name, dataset, bar (m), transform
    EXTRA_VARIANTS                             # more rows: Intel's variants, chains, noise
    make_variant(variant, cache_dir) -> VariantFiles      # log + relations, generated once
    score_run(trajectory, frame, files) -> RunScore       # relations metric on every relation
    fill_dropped_scans(trajectory, odometry) -> Trajectory

Transforms
----------
Each transform rewrites a CARMEN log (``FLASER`` + ``ODOM`` lines) text line by text line;
time stamps, comments and every field it does not name are left as logged, so the log's
relations still apply (rewritten only by :class:`MoveOdometryToCentre`):

:class:`DecimateScans`
    Keep every ``every``-th ``FLASER`` line, counting from the ``start``-th (0-based); every
    ``ODOM`` line is kept.
:class:`ClipRanges`
    Readings above ``limit_m`` become the log's no-return value (``no_return_m``); the scans
    are written as ``ROBOTLASER1`` lines whose maximum range is that value (a ``FLASER`` line
    cannot say which reading means no return), with the source's beam layout.
:class:`BiasOdometry`
    The ``ODOM`` lines' poses are re-integrated with every increment ``(dx, dy, dθ)`` (in the
    frame of the previous ``ODOM`` pose) changed to ``(s·dx, s·dy, dθ + b·|dθ|)``; a
    ``FLASER`` line's odometry pose (``odom_x odom_y odom_theta``) is the last rewritten
    ``ODOM`` pose composed with its own increment from that line, biased the same way (the
    reader's model of laser lines between odometry messages), and its laser pose keeps its
    logged offset from the odometry pose; an ``ODOM`` line's ``tv`` becomes ``s·tv`` and
    ``rv`` becomes ``rv + b·|rv|``.
:class:`NoisyOdometry`
    The same re-integration with random noise added to every increment: normal, independent,
    of variances proportional to the increment's length and turn (a random walk whose spread
    does not depend on how often the odometry was logged), drawn from a seed.
:class:`RangeNoise`
    Normal noise added to every reading that is a return, drawn from a seed (a laser noisier
    than the one the configuration describes); written as ``ROBOTLASER1`` like
    :class:`ClipRanges`.
:class:`MoveOdometryToCentre`
    The laser poses of the ``FLASER`` lines stay; the odometry poses (``FLASER`` ``odom_*`` and
    ``ODOM`` ``x y theta``) move to a robot centre ``pose_laser_centre`` from the laser
    (``centre = laser ∘ T``), and the relations are rewritten for the centre,
    ``rel_c = T⁻¹ ∘ rel_l ∘ T``.  The source's laser and odometry poses must coincide (true of
    the three public logs), so an ``ODOM`` pose is a laser pose.
:class:`DecimateBeams`
    Every ``every``-th beam from the first; the scans are written as ``ROBOTLASER1`` lines,
    which state their geometry (start angle, field of view ``= step·(n − 1)``, angular
    resolution, maximum range); laser and robot pose are the ``FLASER`` line's two poses.
:class:`CropFieldOfView`
    Only the beams within ``±fov_rad/2`` of the laser's forward direction (a narrower scanner:
    a 60° field of view is that of a depth camera's scan); written as ``ROBOTLASER1`` with
    the kept beams' geometry like :class:`DecimateBeams`.
:class:`Chain`
    Several of the above, each applied to the previous one's output (only the last may write
    ``ROBOTLASER1`` lines); the relations go through every step.

A variant log is a log the dataset catalogue does not know: it is named after the variant
(``<cache>/<variant>-<key>/aces-every3.clf``), so none of the catalogue's facts about the source's
sensor apply to it (the beam layout of ``FLASER`` lines then follows CARMEN's rule, which gives
the same bearings for the three logs; the range limit is the reader's default 80 m, so ACES's
clipped 50.00 m readings read as returns; fr079's 0.04 m mounting is not applied).  With
``catalogued_name=True`` it keeps the source's file name (``.../aces.clf``) and the catalogue's
facts apply as to the original.  The relations file is written beside it.  Variants are cached
under a key made of the source log's sha256, the transform's parameters and the naming.

Scoring
-------
:func:`score_run` evaluates a run's ``trajectory.tum`` (in the frame the run reports; never
converted, so a run that reports the wrong frame is penalised) with the Kümmerle relations
metric on **every** relation (``max_unmatched_fraction = 0``).  A scan that a variant dropped
takes the pose of the last kept scan composed with the odometry between the two, taken from the
source log: ``pose(dropped) = pose(kept) ∘ odom(kept)⁻¹ ∘ odom(dropped)``
(:func:`fill_dropped_scans`; the odometry of the frame the run reports, as logged:
``odometry_sign = "logged"``, the poses of the log's lines; ``"velocity"`` would take the
odometry as the estimators read it, with fr079's hidden reversing repaired).  The odometry
baseline is the variant's own logged odometry in the frame of the relations: base poses for the
centre relations of :class:`MoveOdometryToCentre`, laser poses otherwise (filled in the same way
where scans were dropped, i.e. the source's odometry).  Both are also scored on the relations
with ``|t2 − t1| < 10 s``.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import shutil
import tempfile
from collections.abc import Iterable, Iterator
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, ClassVar, Literal

import numpy as np
from numpy.typing import NDArray

from slam.errors import ConfigError, EvaluationError, InputError, LogFormatError
from slam.evaluation.relations_metric import RelationsMetric, relations_metric
from slam.evaluation.timestamps import match_timestamps
from slam.geometry import pose_between, pose_compose, pose_inverse
from slam.io._text import iter_text_lines
from slam.io.carmen import scan_trajectory
from slam.io.catalog import resolve_log, sha256_file
from slam.io.relations import Relations, read_relations, write_relations
from slam.io.trajectory import Trajectory

__all__ = [
    "EXTRA_VARIANTS",
    "SHORT_RELATION_S",
    "VARIANTS",
    "BiasOdometry",
    "Chain",
    "ClipRanges",
    "CropFieldOfView",
    "DecimateBeams",
    "DecimateScans",
    "FreezeOdometry",
    "LogTransform",
    "MoveOdometryToCentre",
    "NoisyOdometry",
    "RangeNoise",
    "RunScore",
    "Variant",
    "VariantFiles",
    "arithmetic",
    "arithmetic_difference",
    "default_cache_dir",
    "fill_dropped_scans",
    "make_variant",
    "rewrite_lines",
    "score_run",
    "variant_by_name",
]

FloatArray = NDArray[np.float64]
Frame = Literal["laser", "base"]


def arithmetic() -> dict[str, Any]:
    """What decides the last bits of this process's arithmetic, for a results file.

    ``{"cpu": model name (``/proc/cpuinfo``; "" where unreadable), "blas": [architectures of
    the BLAS libraries loaded], "numpy_loops": [instruction sets of numpy's loops in use]}``
    (:func:`slam.blas.kernels_in_use`).  Two runs of the same code whose entries differ can
    differ by which loop closures pass (README, What the numbers do not show).
    """
    from slam.blas import cpu_field, kernels_in_use

    kernels = kernels_in_use()
    return {
        "cpu": cpu_field("model name"),
        "blas": sorted({str(lib["architecture"]) for lib in kernels["libraries"]}),
        "numpy_loops": list(kernels.get("numpy_loops", [])),
    }


def arithmetic_difference(before: dict[str, Any] | None, after: dict[str, Any]) -> str | None:
    """How two runs' :func:`arithmetic` differ, as a sentence; None where they agree.

    ``before`` is None for a results file written without the entry (the difference is then
    unknown, and said so).
    """
    if before is None:
        return "the baseline does not record its arithmetic (CPU, BLAS kernels, numpy's loops)"
    names = {"cpu": "CPU", "blas": "BLAS kernels", "numpy_loops": "numpy's loops"}
    parts = [
        f"{label} {before.get(key)} → {after.get(key)}"
        for key, label in names.items()
        if before.get(key) != after.get(key)
    ]
    return "; ".join(parts) if parts else None


#: Relations with ``|t2 − t1|`` below this (s) are also scored on their own.
SHORT_RELATION_S = 10.0
#: Bump when a transform's output changes for the same parameters (invalidates the cache).
MAKER_VERSION = 2
_STAMP_TOL_S = 1e-5


# ---------------------------------------------------------------------------------------------
# Lines of a CARMEN log
# ---------------------------------------------------------------------------------------------
_OTHER_LASERS = ("RLASER", "ROBOTLASER1", "RAWLASER1", "RAWLASER2", "RAWLASER3", "RAWLASER4")


def _flaser_beams(tokens: list[str], where: str) -> int:
    """Beam count of a ``FLASER`` line whose fields are all there (else LogFormatError)."""
    try:
        n = int(tokens[1])
    except (IndexError, ValueError):
        raise LogFormatError("FLASER without a beam count", where) from None
    if n < 1 or len(tokens) < n + 9:
        raise LogFormatError(f"FLASER with {n} readings has only {len(tokens)} fields", where)
    return n


def _pose(tokens: list[str], start: int, where: str) -> FloatArray:
    try:
        return np.array([float(v) for v in tokens[start : start + 3]])
    except ValueError:
        raise LogFormatError("pose field is not a number", where) from None


def _pose_tokens(pose: FloatArray) -> list[str]:
    return [f"{pose[0]:.6f}", f"{pose[1]:.6f}", f"{pose[2]:.6f}"]


def _join(tokens: list[str]) -> str:
    return " ".join(tokens) + "\n"


def _readings(tokens: list[str], n: int, where: str) -> tuple[list[str], FloatArray]:
    """A ``FLASER`` line's ``n`` readings as logged and as numbers (else LogFormatError)."""
    readings = tokens[2 : 2 + n]
    try:
        return readings, np.array([float(v) for v in readings])
    except ValueError:
        raise LogFormatError("range reading is not a number", where) from None


def _robotlaser(
    tokens: list[str], n: int, readings: list[str], first_rad: float, step_rad: float, max_m: float
) -> str:
    """A ``FLASER`` line (``tokens``, ``n`` readings) as ``ROBOTLASER1`` with ``readings``.

    Field of view ``= step·(len(readings) − 1)``; laser and robot pose are the ``FLASER``
    line's ``x y theta`` and ``odom_x odom_y odom_theta``; no remissions; velocities, safety
    distances and turn axis 0; time stamp, hostname and logger time stamp as logged.
    """
    m = len(readings)
    out = ["ROBOTLASER1", "0", repr(first_rad), repr(step_rad * (m - 1)), repr(step_rad)]
    out += [repr(max_m), "0", "0", str(m), *readings, "0", *tokens[2 + n : 8 + n]]
    out += ["0", "0", "0", "0", "0", *tokens[8 + n :]]
    return _join(out)


@dataclass
class _Pass:
    """What a transform carries from line to line during one pass over a log."""

    laser_lines: int = 0
    #: Odometry pose of the last ``ODOM`` line (else of the last laser line, while no ``ODOM``
    #: line has come), as logged and as rewritten.
    odometry: tuple[FloatArray, FloatArray] | None = None
    odom_lines: int = 0
    #: Random draws of the pass (a transform that needs them seeds it at its first use).
    rng: np.random.Generator | None = None
    #: What a transform remembers of earlier lines (:class:`OdometryLag`).
    history: dict[str, Any] | None = None


class LogTransform:
    """A rewrite of a ``FLASER`` + ``ODOM`` CARMEN log, line by line (module docstring).

    Subclasses are frozen dataclasses (their fields are the parameters, which key the cache)
    and rewrite one message at a time (``_line``); what they carry from line to line lives in
    the pass's state, so one transform can rewrite several logs, also at once.
    """

    kind: ClassVar[str] = ""
    #: Frame of the poses the (rewritten) relations refer to.
    relations_frame: ClassVar[Frame] = "laser"

    def params(self) -> dict[str, Any]:
        """The parameters, with the transform's kind (JSON-ready)."""
        return {"kind": self.kind, **asdict(self)}  # type: ignore[call-overload]

    def rewrite(self, lines: Iterable[tuple[int, str]], source: str) -> Iterator[str]:
        """The variant's lines (newline-terminated) from ``(line_number, text)`` of the source.

        Raises
        ------
        LogFormatError
            A malformed ``FLASER``/``ODOM`` line (file and line named), or a laser message
            other than ``FLASER``.
        """
        state = _Pass()
        for number, text in lines:
            tokens = text.split()
            if not tokens or tokens[0].startswith("#"):
                yield text if text.endswith("\n") else text + "\n"
                continue
            where = f"{source}:{number}"
            if tokens[0] in _OTHER_LASERS:
                raise LogFormatError(f"{tokens[0]}: the variants rewrite FLASER logs only", where)
            yield from self._line(tokens, where, state)

    def _line(
        self, tokens: list[str], where: str, state: _Pass
    ) -> Iterator[str]:  # pragma: no cover
        raise NotImplementedError

    def relations(self, relations: Relations) -> Relations:
        """The relations of the variant (unchanged unless the transform moves the frame)."""
        return relations


def rewrite_lines(
    transform: LogTransform, lines: Iterable[str], source: str = "<lines>"
) -> list[str]:
    """``transform`` applied to a log given as text lines (for tests and small logs)."""
    return list(transform.rewrite(enumerate(lines, start=1), source))


@dataclass(frozen=True)
class DecimateScans(LogTransform):
    """Keep every ``every``-th ``FLASER`` line from the ``start``-th (0-based); all ``ODOM``."""

    every: int
    start: int = 0
    kind: ClassVar[str] = "decimate-scans"

    def __post_init__(self) -> None:
        if self.every < 1 or not 0 <= self.start < self.every:
            raise ConfigError(f"need every >= 1 and 0 <= start < every, got {self}")

    def _line(self, tokens: list[str], where: str, state: _Pass) -> Iterator[str]:
        if tokens[0] != "FLASER":
            yield _join(tokens)
            return
        _flaser_beams(tokens, where)
        index = state.laser_lines
        state.laser_lines += 1
        if index >= self.start and (index - self.start) % self.every == 0:
            yield _join(tokens)


class _ScanAsRobotLaser(LogTransform):
    """Every ``FLASER`` line written as a ``ROBOTLASER1`` line (``_scan``); others as logged.

    Only the last step of a :class:`Chain` may be one (the others rewrite ``FLASER`` logs).
    """

    def _line(self, tokens: list[str], where: str, state: _Pass) -> Iterator[str]:
        if tokens[0] != "FLASER":
            yield _join(tokens)
            return
        yield self._scan(tokens, _flaser_beams(tokens, where), where, state)

    def _scan(self, tokens: list[str], n: int, where: str, state: _Pass) -> str:  # pragma: no cover
        raise NotImplementedError


@dataclass(frozen=True)
class ClipRanges(_ScanAsRobotLaser):
    """Readings above ``limit_m`` become ``no_return_m``; written as ``ROBOTLASER1``.

    A ``FLASER`` line cannot say which reading means "no return", so the variant's scans are
    written as ``ROBOTLASER1`` lines whose maximum range is ``no_return_m`` (the source's
    no-return reading), with the source's beam layout ``first_angle_rad``, ``step_rad``.
    """

    limit_m: float
    no_return_m: float
    first_angle_rad: float
    step_rad: float
    kind: ClassVar[str] = "clip-ranges"

    def __post_init__(self) -> None:
        if not (0.0 < self.limit_m < self.no_return_m and self.step_rad > 0.0):
            raise ConfigError(f"need 0 < limit_m < no_return_m and step_rad > 0, got {self}")

    def _scan(self, tokens: list[str], n: int, where: str, state: _Pass) -> str:
        token = f"{self.no_return_m:.2f}"
        if float(token) != self.no_return_m:
            token = repr(self.no_return_m)
        readings, ranges = _readings(tokens, n, where)
        readings = [token if r > self.limit_m else v for r, v in zip(ranges, readings, strict=True)]
        return _robotlaser(
            tokens, n, readings, self.first_angle_rad, self.step_rad, self.no_return_m
        )


@dataclass(frozen=True)
class RangeNoise(_ScanAsRobotLaser):
    """Normal noise of ``sigma_m`` added to every reading that is a return; ``ROBOTLASER1``.

    A reading at or above ``no_return_m`` (the source's no-return value) or at or below 0 is
    kept as logged, as is one that the noise would carry to or past either; the others become
    ``r + n``, ``n ~ N(0, sigma_m²)`` independent per beam, drawn from ``seed`` (one generator
    per pass over a log), written to the millimetre.  The scans are written as ``ROBOTLASER1``
    lines with the source's beam layout and ``no_return_m`` as their maximum range, as
    :class:`ClipRanges` writes them.
    """

    sigma_m: float
    no_return_m: float
    first_angle_rad: float
    step_rad: float
    seed: int = 0
    kind: ClassVar[str] = "range-noise"

    def __post_init__(self) -> None:
        if not (math.isfinite(self.sigma_m) and self.sigma_m >= 0.0):
            raise ConfigError(f"RangeNoise.sigma_m must be finite and >= 0, got {self.sigma_m}")
        if not (self.no_return_m > 0.0 and self.step_rad > 0.0):
            raise ConfigError(f"need no_return_m > 0 and step_rad > 0, got {self}")

    def _scan(self, tokens: list[str], n: int, where: str, state: _Pass) -> str:
        if state.rng is None:
            state.rng = np.random.default_rng(self.seed)
        readings, ranges = _readings(tokens, n, where)
        noisy = ranges + self.sigma_m * state.rng.standard_normal(n)
        inside = (ranges > 0.0) & (ranges < self.no_return_m)
        changed = inside & (noisy > 0.0) & (noisy < self.no_return_m)
        out = [f"{r:.3f}" if c else v for r, c, v in zip(noisy, changed, readings, strict=True)]
        return _robotlaser(tokens, n, out, self.first_angle_rad, self.step_rad, self.no_return_m)


class _ReintegratedOdometry(LogTransform):
    """Odometry re-integrated with every increment rewritten (``_increment``).

    The ``ODOM`` lines are the odometry's chain: each one's increment from the previous
    ``ODOM`` line is rewritten and integrated.  A ``FLASER`` line's odometry pose is the
    rewritten pose of the last ``ODOM`` line composed with its own rewritten increment from that
    line (as :func:`slam.io.carmen.velocity_signed_scans` reads laser lines); before the first
    ``ODOM`` line (or in a log without any) laser lines chain on each other.  The laser pose of
    a ``FLASER`` line keeps its logged offset from the odometry pose.
    """

    def _increment(self, d: FloatArray, state: _Pass) -> FloatArray:  # pragma: no cover
        raise NotImplementedError

    def _velocities(self, tv: float, rv: float) -> tuple[float, float] | None:
        """An ``ODOM`` line's rewritten ``tv``, ``rv`` (None: as logged)."""
        return None

    def _rewritten(
        self, previous: tuple[FloatArray, FloatArray] | None, raw: FloatArray, state: _Pass
    ) -> FloatArray:
        if previous is None:
            return raw.copy()
        return pose_compose(previous[1], self._increment(pose_between(previous[0], raw), state))

    def _line(self, tokens: list[str], where: str, state: _Pass) -> Iterator[str]:
        if tokens[0] == "ODOM":
            if len(tokens) < 8:
                raise LogFormatError("ODOM with fewer than 8 fields", where)
            raw = _pose(tokens, 1, where)
            new = self._rewritten(state.odometry, raw, state)
            state.odometry = (raw, new)
            state.odom_lines += 1
            tokens[1:4] = _pose_tokens(new)
            try:
                velocities = self._velocities(float(tokens[4]), float(tokens[5]))
            except ValueError:
                raise LogFormatError("ODOM tv or rv is not a number", where) from None
            if velocities is not None:
                tokens[4:6] = [f"{velocities[0]:.6f}", f"{velocities[1]:.6f}"]
        elif tokens[0] == "FLASER":
            n = _flaser_beams(tokens, where)
            laser = _pose(tokens, 2 + n, where)
            base = _pose(tokens, 5 + n, where)
            new = self._rewritten(state.odometry, base, state)
            if state.odom_lines == 0:
                state.odometry = (base, new)
            tokens[2 + n : 5 + n] = _pose_tokens(pose_compose(new, pose_between(base, laser)))
            tokens[5 + n : 8 + n] = _pose_tokens(new)
        yield _join(tokens)


@dataclass(frozen=True)
class FreezeOdometry(_ReintegratedOdometry):
    """A log whose odometry never moves, as a laser-only recording writes it.

    Every increment is zero: every pose of ``ODOM`` and ``FLASER`` lines (the laser pose and the
    odometry pose) is the log's first one (the laser pose keeps its logged offset), ``tv`` and
    ``rv`` are zero.
    """

    kind: ClassVar[str] = "freeze-odometry"

    def _increment(self, d: FloatArray, state: _Pass) -> FloatArray:
        return np.zeros(3)

    def _velocities(self, tv: float, rv: float) -> tuple[float, float] | None:
        return 0.0, 0.0


@dataclass(frozen=True)
class BiasOdometry(_ReintegratedOdometry):
    """Odometry re-integrated with ``(dx, dy, dθ) → (s·dx, s·dy, dθ + b·|dθ|)``.

    See :class:`_ReintegratedOdometry` for which increments; an ``ODOM`` line's ``tv`` becomes
    ``s·tv`` and ``rv`` becomes ``rv + b·|rv|``.
    """

    translation_scale: float
    heading_bias: float
    kind: ClassVar[str] = "bias-odometry"

    def _increment(self, d: FloatArray, state: _Pass) -> FloatArray:
        return np.array(
            [
                self.translation_scale * d[0],
                self.translation_scale * d[1],
                d[2] + self.heading_bias * abs(d[2]),
            ]
        )

    def _velocities(self, tv: float, rv: float) -> tuple[float, float] | None:
        return self.translation_scale * tv, rv + self.heading_bias * abs(rv)


@dataclass(frozen=True)
class NoisyOdometry(_ReintegratedOdometry):
    """Odometry re-integrated with random noise added to every increment (a random walk).

    An increment ``d = (dx, dy, dθ)`` becomes ``d + (n_x, n_y, n_θ)`` with independent normal
    components of variances ``var_xy_per_m·ℓ`` (``n_x``, ``n_y``) and ``var_theta_per_m·ℓ +
    var_theta_per_rad·|dθ|`` (``n_θ``), ``ℓ = hypot(dx, dy)``: the variances grow with the
    path and the turning, not with the number of increments, so the accumulated error does not
    depend on how often the odometry was logged.  The draws come from ``seed`` (one generator
    per pass over a log).  Velocities are kept as logged.
    """

    var_xy_per_m: float
    var_theta_per_m: float
    var_theta_per_rad: float
    seed: int = 0
    kind: ClassVar[str] = "noisy-odometry"

    def __post_init__(self) -> None:
        for name in ("var_xy_per_m", "var_theta_per_m", "var_theta_per_rad"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ConfigError(f"NoisyOdometry.{name} must be finite and >= 0, got {value}")

    def _increment(self, d: FloatArray, state: _Pass) -> FloatArray:
        if state.rng is None:
            state.rng = np.random.default_rng(self.seed)
        length = math.hypot(float(d[0]), float(d[1]))
        sigma_xy = math.sqrt(self.var_xy_per_m * length)
        sigma_theta = math.sqrt(self.var_theta_per_m * length + self.var_theta_per_rad * abs(d[2]))
        noise = state.rng.standard_normal(3) * np.array([sigma_xy, sigma_xy, sigma_theta])
        return np.asarray(d, dtype=float) + noise


@dataclass(frozen=True)
class OdometryLag(LogTransform):
    """The odometry ``scans`` laser lines late, as a logger that pairs each scan with old odometry.

    The ``k``-th ``FLASER`` line (0-based) carries the odometry pose of line ``k − scans``
    (of the first line while ``k < scans``); its laser pose keeps its logged offset from the
    odometry pose.  The ``ODOM`` lines logged between laser lines ``k − 1`` and ``k`` keep their
    time stamps and places in the file but carry the pose, ``tv`` and ``rv`` of the last
    ``ODOM`` line before laser line ``k − scans`` (of the first ``ODOM`` line while there is
    none), so that both streams are delayed alike and a laser line's increment from the last
    ``ODOM`` line is the delayed one.  Over a gap in the log a line's odometry is as old as
    the gap.
    """

    scans: int
    kind: ClassVar[str] = "odometry-lag"

    def __post_init__(self) -> None:
        if self.scans < 0:
            raise ConfigError(f"OdometryLag.scans must be >= 0, got {self.scans}")

    def _line(self, tokens: list[str], where: str, state: _Pass) -> Iterator[str]:
        if state.history is None:
            # laser lines' odometry poses; per laser line, the last ODOM fields before it
            state.history = {"laser": [], "odom_before": [], "odom_first": None, "odom_last": None}
        history = state.history
        if tokens[0] == "ODOM":
            if len(tokens) < 8:
                raise LogFormatError("ODOM with fewer than 8 fields", where)
            _pose(tokens, 1, where)
            own = tokens[1:6]  # x y theta tv rv
            history["odom_first"] = history["odom_first"] or own
            history["odom_last"] = own
            k = len(history["laser"]) - self.scans
            if k >= len(history["odom_before"]):  # no lag: this line itself
                delayed = own
            else:
                delayed = (history["odom_before"][k] if k >= 0 else None) or history["odom_first"]
            tokens[1:6] = delayed
        elif tokens[0] == "FLASER":
            n = _flaser_beams(tokens, where)
            laser = _pose(tokens, 2 + n, where)
            base = _pose(tokens, 5 + n, where)
            history["laser"].append(base)
            history["odom_before"].append(history["odom_last"])
            k = max(0, len(history["laser"]) - 1 - self.scans)
            old = history["laser"][k]
            tokens[2 + n : 5 + n] = _pose_tokens(pose_compose(old, pose_between(base, laser)))
            tokens[5 + n : 8 + n] = _pose_tokens(old)
        yield _join(tokens)


@dataclass(frozen=True)
class MoveOdometryToCentre(LogTransform):
    """Odometry poses moved to ``laser ∘ pose_laser_centre``; relations rewritten for it."""

    pose_laser_centre: tuple[float, float, float]
    kind: ClassVar[str] = "move-odometry"
    relations_frame: ClassVar[Frame] = "base"
    #: Largest difference between a source line's laser and odometry pose (m or rad).
    same_pose_tol: ClassVar[float] = 1e-6

    @property
    def _t(self) -> FloatArray:
        return np.asarray(self.pose_laser_centre, dtype=float)

    def _line(self, tokens: list[str], where: str, state: _Pass) -> Iterator[str]:
        if tokens[0] == "ODOM":
            if len(tokens) < 8:
                raise LogFormatError("ODOM with fewer than 8 fields", where)
            tokens[1:4] = _pose_tokens(pose_compose(_pose(tokens, 1, where), self._t))
        elif tokens[0] == "FLASER":
            n = _flaser_beams(tokens, where)
            laser = _pose(tokens, 2 + n, where)
            base = _pose(tokens, 5 + n, where)
            d = pose_between(base, laser)
            if np.abs(d).max() > self.same_pose_tol:
                raise LogFormatError(
                    "laser and odometry poses differ; the mount variant needs a log whose "
                    "laser poses are its odometry poses",
                    where,
                )
            tokens[5 + n : 8 + n] = _pose_tokens(pose_compose(laser, self._t))
        yield _join(tokens)

    def relations(self, relations: Relations) -> Relations:
        """``T⁻¹ ∘ rel ∘ T`` for every relation (planar; z, roll, pitch kept)."""
        t = np.broadcast_to(self._t, relations.poses.shape)
        poses = pose_compose(pose_compose(pose_inverse(t), relations.poses), t)
        return Relations(
            relations.t1,
            relations.t2,
            poses,
            relations.z,
            relations.roll,
            relations.pitch,
            relations.line_numbers,
        )


@dataclass(frozen=True)
class DecimateBeams(_ScanAsRobotLaser):
    """Every ``every``-th beam from the first, written as ``ROBOTLASER1`` with its geometry.

    ``first_angle_rad``, ``step_rad`` and ``max_range_m`` are those of the source's ``FLASER``
    lines (the catalogue's laser facts).
    """

    every: int
    first_angle_rad: float
    step_rad: float
    max_range_m: float
    kind: ClassVar[str] = "decimate-beams"

    def __post_init__(self) -> None:
        if self.every < 1 or not (self.step_rad > 0.0 and self.max_range_m > 0.0):
            raise ConfigError(f"need every >= 1, step_rad > 0, max_range_m > 0, got {self}")

    def _scan(self, tokens: list[str], n: int, where: str, state: _Pass) -> str:
        kept = tokens[2 : 2 + n : self.every]
        step = self.every * self.step_rad
        return _robotlaser(tokens, n, kept, self.first_angle_rad, step, self.max_range_m)


@dataclass(frozen=True)
class CropFieldOfView(_ScanAsRobotLaser):
    """The beams whose bearing lies within ``±fov_rad/2``, as ``ROBOTLASER1`` with their geometry.

    ``first_angle_rad``, ``step_rad`` and ``max_range_m`` are those of the source's ``FLASER``
    lines (the catalogue's laser facts); the kept beams are consecutive, so the field of view
    written is ``step·(kept − 1)``, at most ``fov_rad``.
    """

    fov_rad: float
    first_angle_rad: float
    step_rad: float
    max_range_m: float
    kind: ClassVar[str] = "crop-fov"

    def __post_init__(self) -> None:
        if not (self.fov_rad > 0.0 and self.step_rad > 0.0 and self.max_range_m > 0.0):
            raise ConfigError(f"need fov_rad > 0, step_rad > 0, max_range_m > 0, got {self}")

    def _scan(self, tokens: list[str], n: int, where: str, state: _Pass) -> str:
        bearings = self.first_angle_rad + self.step_rad * np.arange(n)
        kept = np.flatnonzero(np.abs(bearings) <= 0.5 * self.fov_rad + 1e-9)
        if kept.size < 2:
            raise LogFormatError(
                f"a {math.degrees(self.fov_rad):g}° field of view keeps {kept.size} of {n} beams",
                where,
            )
        readings = tokens[2 + int(kept[0]) : 3 + int(kept[-1])]
        first = float(bearings[kept[0]])
        return _robotlaser(tokens, n, readings, first, self.step_rad, self.max_range_m)


@dataclass(frozen=True)
class Chain(LogTransform):
    """``steps`` applied one after the other (each to the previous one's output).

    Only the last step may write ``ROBOTLASER1`` lines (the others rewrite ``FLASER`` logs);
    the relations go through every step, and refer to the robot centre if a step moves them
    there.
    """

    steps: tuple[LogTransform, ...]
    kind: ClassVar[str] = "chain"

    def __post_init__(self) -> None:
        if len(self.steps) < 2:
            raise ConfigError(f"a chain needs at least two steps, got {len(self.steps)}")
        for step in self.steps[:-1]:
            if isinstance(step, (_ScanAsRobotLaser, Chain)):
                raise ConfigError(
                    f"{step.kind} writes ROBOTLASER1 lines (or is a chain): only the last step may"
                )

    @property
    def relations_frame(self) -> Frame:  # type: ignore[override]
        """``"base"`` if a step moves the relations to the robot centre, else ``"laser"``."""
        frames = [s.relations_frame for s in self.steps]
        return "base" if "base" in frames else "laser"

    def params(self) -> dict[str, Any]:
        """The kind and every step's parameters, in order."""
        return {"kind": self.kind, "steps": [s.params() for s in self.steps]}

    def rewrite(self, lines: Iterable[tuple[int, str]], source: str) -> Iterator[str]:
        """The lines of the last step, fed by the previous ones (see :meth:`LogTransform.rewrite`).

        A malformed line is named by its number in ``source``'s ``steps[0]`` input; later steps
        number their input lines as they come.
        """
        out: Iterable[str] = self.steps[0].rewrite(lines, source)
        for k, step in enumerate(self.steps[1:], start=1):
            out = step.rewrite(enumerate(out, start=1), f"{source} (after step {k})")
        yield from out

    def relations(self, relations: Relations) -> Relations:
        """The relations through every step."""
        for step in self.steps:
            relations = step.relations(relations)
        return relations


# ---------------------------------------------------------------------------------------------
# The table of variants
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Variant:
    """One row of the robustness table.

    Attributes
    ----------
    name : str
        Row name (``--only``).
    dataset : str
        Catalogued source log.
    bar_m : float
        Mean absolute translation error (m) the run should stay within.
    transform : LogTransform or None
        ``None``: the log as it is.
    description : str
        One line for the table's notes.
    """

    name: str
    dataset: str
    bar_m: float
    transform: LogTransform | None
    description: str = ""

    def params(self) -> dict[str, Any]:
        """JSON-ready description (name, dataset, bar, transform parameters)."""
        return {
            "name": self.name,
            "dataset": self.dataset,
            "bar_m": self.bar_m,
            "transform": None if self.transform is None else self.transform.params(),
            "description": self.description,
        }


_HALF_PI = math.pi / 2.0
_FR079_STEP_RAD = math.radians(0.5)
_ONE_DEG_RAD = math.radians(1.0)
_FR079_NO_RETURN_M = 81.91
_ACES_NO_RETURN_M = 50.0
_INTEL_NO_RETURN_M = 81.83

VARIANTS: tuple[Variant, ...] = (
    Variant("aces-every3", "aces", 0.08, DecimateScans(3), "every 3rd FLASER line"),
    Variant("aces-every4", "aces", 0.08, DecimateScans(4), "every 4th FLASER line"),
    Variant("fr079-every4-from0", "fr079", 0.10, DecimateScans(4, 0), "every 4th from line 0"),
    Variant("fr079-every4-from1", "fr079", 0.10, DecimateScans(4, 1), "every 4th from line 1"),
    Variant("fr079-every4-from2", "fr079", 0.10, DecimateScans(4, 2), "every 4th from line 2"),
    Variant(
        "aces-max8m",
        "aces",
        0.08,
        ClipRanges(8.0, _ACES_NO_RETURN_M, -_HALF_PI, _ONE_DEG_RAD),
        "readings > 8 m set to no return (50.00), ROBOTLASER1",
    ),
    Variant(
        "fr079-max8m",
        "fr079",
        0.10,
        ClipRanges(8.0, _FR079_NO_RETURN_M, -_HALF_PI, _FR079_STEP_RAD),
        "readings > 8 m set to no return (81.91), ROBOTLASER1",
    ),
    Variant(
        "fr079-odom-bias",
        "fr079",
        0.10,
        BiasOdometry(1.02, 0.02),
        "odometry translation x1.02, heading increments dθ + 0.02|dθ|",
    ),
    Variant(
        "aces-mount-0.2",
        "aces",
        0.05,
        MoveOdometryToCentre((-0.2, 0.0, 0.0)),
        "laser 0.2 m ahead of the odometry centre; relations for the centre",
    ),
    Variant(
        "fr079-beams90",
        "fr079",
        0.10,
        DecimateBeams(4, -_HALF_PI, _FR079_STEP_RAD, _FR079_NO_RETURN_M),
        "every 4th beam (90 beams, 2°), ROBOTLASER1",
    ),
    Variant(
        "fr079-beams180",
        "fr079",
        0.10,
        DecimateBeams(2, -_HALF_PI, _FR079_STEP_RAD, _FR079_NO_RETURN_M),
        "every 2nd beam (180 beams, 1°), ROBOTLASER1",
    ),
    Variant("intel", "intel", 0.03, None, "unmodified"),
    Variant("aces", "aces", 0.045, None, "unmodified"),
    Variant("fr079", "fr079", 0.08, None, "unmodified"),
)


#: Random odometry noise of the ``*-odom-noise`` rows: σ 5 cm per √m in x and in y, heading
#: σ 0.05 rad per √m and 0.1 rad per √rad turned (variances per metre and per radian).
_ODOM_NOISE_VAR_XY = 0.05**2
_ODOM_NOISE_VAR_THETA_M = 0.05**2
_ODOM_NOISE_VAR_THETA_RAD = 0.1**2
_ODOM_NOISE = "odometry noise: σ 5 cm/√m in x and y, heading 0.05 rad/√m + 0.1 rad/√rad, seed 0"

#: Range noise of the ``*-range-noise`` rows: a laser noisier than the configured 5 mm (σ 2 cm
#: added to every return, as a Hokuyo UTM-30LX's stated ±3 cm).
_RANGE_NOISE_SIGMA_M = 0.02
_RANGE_NOISE = "range noise: σ 2 cm added to every return, seed 0, ROBOTLASER1"

#: ``aces-mount-yaw``: the laser's pose in the robot's frame is ``(0.2 m, 0, 0.5 rad)``.
_YAW_MOUNT: tuple[float, float, float] = (
    -0.2 * math.cos(0.5),
    0.2 * math.sin(0.5),
    -0.5,
)

#: The ``*-fov60`` rows: only the middle 60° of the scan (a depth camera's field of view).
_FOV_60_RAD = math.radians(60.0)
_FOV_60 = "field of view 60° (the middle beams, ±30°), ROBOTLASER1"
_NO_ODOMETRY = "odometry frozen at its first pose (a laser-only log): the motion from the scans"

#: The ``*-max5.6m`` rows: a short-range scanner (a Hokuyo URG-04LX reaches 5.6 m).
_SHORT_RANGE_M = 5.6
_SHORT_RANGE = "readings > 5.6 m set to no return (a Hokuyo URG-04LX's range), ROBOTLASER1"
#: The ``*-odom-lag1`` rows: each scan paired with the odometry of the laser line before it.
_LAG = "odometry one laser line late (about 0.2 s; over a gap in the log, as old as the gap)"

#: More rows, never used to choose a default before they were added (the ``*-fov60`` rows
#: are among those the handling of a contradicted scan match was judged on): the same
#: transforms on Intel, chains of two or three transforms on the three logs (a lower scan
#: rate together with a mounted laser, a shorter range, fewer beams or biased odometry), the
#: three logs with noisier odometry, with a noisier laser and with a 60° field of view, and
#: ACES with its laser turned against the robot's heading.  Intel's bar is its own plus
#: 0.02 m; a chain's (and a noise or field-of-view row's) is its log's bar for the variants.
#: ``aces-every4-mount-0.22`` is about 1.35 scans/s with the laser 0.22 m ahead of the robot
#: centre.
EXTRA_VARIANTS: tuple[Variant, ...] = (
    Variant("intel-every4", "intel", 0.05, DecimateScans(4), "every 4th FLASER line"),
    Variant(
        "intel-max8m",
        "intel",
        0.05,
        ClipRanges(8.0, _INTEL_NO_RETURN_M, -_HALF_PI, _ONE_DEG_RAD),
        "readings > 8 m set to no return (81.83), ROBOTLASER1",
    ),
    Variant(
        "intel-odom-bias",
        "intel",
        0.05,
        BiasOdometry(1.02, 0.02),
        "odometry translation x1.02, heading increments dθ + 0.02|dθ|",
    ),
    Variant(
        "intel-mount-0.2",
        "intel",
        0.05,
        MoveOdometryToCentre((-0.2, 0.0, 0.0)),
        "laser 0.2 m ahead of the odometry centre; relations for the centre",
    ),
    Variant(
        "intel-beams90",
        "intel",
        0.05,
        DecimateBeams(2, -_HALF_PI, _ONE_DEG_RAD, _INTEL_NO_RETURN_M),
        "every 2nd beam (90 beams, 2°), ROBOTLASER1",
    ),
    Variant(
        "aces-every4-mount-0.22",
        "aces",
        0.08,
        Chain((DecimateScans(4), MoveOdometryToCentre((-0.22, 0.0, 0.0)))),
        "every 4th FLASER line, laser 0.22 m ahead of the odometry centre",
    ),
    Variant(
        "aces-odom-bias",
        "aces",
        0.08,
        BiasOdometry(1.02, 0.02),
        "odometry translation x1.02, heading increments dθ + 0.02|dθ|",
    ),
    Variant(
        "fr079-every2-max8m",
        "fr079",
        0.10,
        Chain(
            (
                DecimateScans(2),
                ClipRanges(8.0, _FR079_NO_RETURN_M, -_HALF_PI, _FR079_STEP_RAD),
            )
        ),
        "every 2nd FLASER line, readings > 8 m set to no return, ROBOTLASER1",
    ),
    Variant(
        "fr079-every2-beams180",
        "fr079",
        0.10,
        Chain(
            (
                DecimateScans(2),
                DecimateBeams(2, -_HALF_PI, _FR079_STEP_RAD, _FR079_NO_RETURN_M),
            )
        ),
        "every 2nd FLASER line, every 2nd beam (180 beams, 1°), ROBOTLASER1",
    ),
    Variant(
        "intel-every4-max8m",
        "intel",
        0.05,
        Chain((DecimateScans(4), ClipRanges(8.0, _INTEL_NO_RETURN_M, -_HALF_PI, _ONE_DEG_RAD))),
        "every 4th FLASER line, readings > 8 m set to no return, ROBOTLASER1",
    ),
    Variant(
        "aces-every4-max8m",
        "aces",
        0.08,
        Chain((DecimateScans(4), ClipRanges(8.0, _ACES_NO_RETURN_M, -_HALF_PI, _ONE_DEG_RAD))),
        "every 4th FLASER line, readings > 8 m set to no return, ROBOTLASER1",
    ),
    Variant(
        "aces-every4-bias-mount-0.22",
        "aces",
        0.08,
        Chain(
            (DecimateScans(4), BiasOdometry(1.02, 0.02), MoveOdometryToCentre((-0.22, 0.0, 0.0)))
        ),
        "every 4th FLASER line, biased odometry, laser 0.22 m ahead of the odometry centre",
    ),
    Variant(
        "fr079-every3-max8m",
        "fr079",
        0.10,
        Chain((DecimateScans(3), ClipRanges(8.0, _FR079_NO_RETURN_M, -_HALF_PI, _FR079_STEP_RAD))),
        "every 3rd FLASER line, readings > 8 m set to no return, ROBOTLASER1",
    ),
    Variant(
        "fr079-every4-odom-bias",
        "fr079",
        0.10,
        Chain((DecimateScans(4), BiasOdometry(1.02, 0.02))),
        "every 4th FLASER line, biased odometry",
    ),
    Variant(
        "intel-odom-noise",
        "intel",
        0.05,
        NoisyOdometry(_ODOM_NOISE_VAR_XY, _ODOM_NOISE_VAR_THETA_M, _ODOM_NOISE_VAR_THETA_RAD),
        _ODOM_NOISE,
    ),
    Variant(
        "aces-odom-noise",
        "aces",
        0.08,
        NoisyOdometry(_ODOM_NOISE_VAR_XY, _ODOM_NOISE_VAR_THETA_M, _ODOM_NOISE_VAR_THETA_RAD),
        _ODOM_NOISE,
    ),
    Variant(
        "fr079-odom-noise",
        "fr079",
        0.10,
        NoisyOdometry(_ODOM_NOISE_VAR_XY, _ODOM_NOISE_VAR_THETA_M, _ODOM_NOISE_VAR_THETA_RAD),
        _ODOM_NOISE,
    ),
    Variant(
        "intel-range-noise",
        "intel",
        0.05,
        RangeNoise(_RANGE_NOISE_SIGMA_M, _INTEL_NO_RETURN_M, -_HALF_PI, _ONE_DEG_RAD),
        _RANGE_NOISE,
    ),
    Variant(
        "aces-range-noise",
        "aces",
        0.08,
        RangeNoise(_RANGE_NOISE_SIGMA_M, _ACES_NO_RETURN_M, -_HALF_PI, _ONE_DEG_RAD),
        _RANGE_NOISE,
    ),
    Variant(
        "fr079-range-noise",
        "fr079",
        0.10,
        RangeNoise(_RANGE_NOISE_SIGMA_M, _FR079_NO_RETURN_M, -_HALF_PI, _FR079_STEP_RAD),
        _RANGE_NOISE,
    ),
    Variant(
        "fr079-every4-beams90",
        "fr079",
        0.10,
        Chain(
            (
                DecimateScans(4),
                DecimateBeams(4, -_HALF_PI, _FR079_STEP_RAD, _FR079_NO_RETURN_M),
            )
        ),
        "every 4th FLASER line, every 4th beam (90 beams, 2°), ROBOTLASER1",
    ),
    Variant(
        "aces-mount-yaw",
        "aces",
        0.08,
        MoveOdometryToCentre(_YAW_MOUNT),
        "laser 0.2 m ahead of the odometry centre, turned 0.5 rad (29°) to the left; "
        "relations for the centre",
    ),
    Variant(
        "intel-fov60",
        "intel",
        0.05,
        CropFieldOfView(_FOV_60_RAD, -_HALF_PI, _ONE_DEG_RAD, _INTEL_NO_RETURN_M),
        _FOV_60,
    ),
    Variant(
        "aces-fov60",
        "aces",
        0.08,
        CropFieldOfView(_FOV_60_RAD, -_HALF_PI, _ONE_DEG_RAD, _ACES_NO_RETURN_M),
        _FOV_60,
    ),
    Variant(
        "fr079-fov60",
        "fr079",
        0.10,
        CropFieldOfView(_FOV_60_RAD, -_HALF_PI, _FR079_STEP_RAD, _FR079_NO_RETURN_M),
        _FOV_60,
    ),
    Variant("intel-no-odometry", "intel", 0.05, FreezeOdometry(), _NO_ODOMETRY),
    Variant("aces-no-odometry", "aces", 0.08, FreezeOdometry(), _NO_ODOMETRY),
    Variant("fr079-no-odometry", "fr079", 0.10, FreezeOdometry(), _NO_ODOMETRY),
    # Rows added after every default of today was chosen (held out): a short-range scanner,
    # odometry paired with the scans one laser line late, and the two with a lower scan rate.
    Variant(
        "intel-max5.6m",
        "intel",
        0.05,
        ClipRanges(_SHORT_RANGE_M, _INTEL_NO_RETURN_M, -_HALF_PI, _ONE_DEG_RAD),
        _SHORT_RANGE,
    ),
    Variant(
        "aces-max5.6m",
        "aces",
        0.08,
        ClipRanges(_SHORT_RANGE_M, _ACES_NO_RETURN_M, -_HALF_PI, _ONE_DEG_RAD),
        _SHORT_RANGE,
    ),
    Variant(
        "fr079-max5.6m",
        "fr079",
        0.10,
        ClipRanges(_SHORT_RANGE_M, _FR079_NO_RETURN_M, -_HALF_PI, _FR079_STEP_RAD),
        _SHORT_RANGE,
    ),
    Variant("intel-odom-lag1", "intel", 0.05, OdometryLag(1), _LAG),
    Variant("aces-odom-lag1", "aces", 0.08, OdometryLag(1), _LAG),
    Variant("fr079-odom-lag1", "fr079", 0.10, OdometryLag(1), _LAG),
    Variant(
        "aces-every2-odom-lag1",
        "aces",
        0.08,
        Chain((DecimateScans(2), OdometryLag(1))),
        "every 2nd FLASER line, odometry one (kept) laser line late",
    ),
    Variant(
        "aces-odom-lag1-max5.6m",
        "aces",
        0.08,
        Chain(
            (
                OdometryLag(1),
                ClipRanges(_SHORT_RANGE_M, _ACES_NO_RETURN_M, -_HALF_PI, _ONE_DEG_RAD),
            )
        ),
        "odometry one laser line late, readings > 5.6 m set to no return, ROBOTLASER1",
    ),
    *(
        Variant(
            f"{name}-every2-lag1-max5.6m",
            name,
            bar,
            Chain(
                (
                    DecimateScans(2),
                    OdometryLag(1),
                    ClipRanges(_SHORT_RANGE_M, no_return, -_HALF_PI, step),
                )
            ),
            "every 2nd FLASER line, odometry one (kept) laser line late, readings > 5.6 m set "
            "to no return, ROBOTLASER1",
        )
        for name, bar, no_return, step in (
            ("intel", 0.05, _INTEL_NO_RETURN_M, _ONE_DEG_RAD),
            ("aces", 0.08, _ACES_NO_RETURN_M, _ONE_DEG_RAD),
            ("fr079", 0.10, _FR079_NO_RETURN_M, _FR079_STEP_RAD),
        )
    ),
)


def variant_by_name(name: str) -> Variant:
    """The row of :data:`VARIANTS` or :data:`EXTRA_VARIANTS` called ``name``."""
    rows = VARIANTS + EXTRA_VARIANTS
    for variant in rows:
        if variant.name == name:
            return variant
    raise ConfigError(f"unknown variant {name!r}; known: {', '.join(v.name for v in rows)}")


# ---------------------------------------------------------------------------------------------
# Making (and caching) a variant
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class VariantFiles:
    """The files of a variant.

    Attributes
    ----------
    variant : Variant
    log : Path
        The variant log (the source log itself for an unmodified row).
    relations : Path
        Its relations (rewritten where the transform moves the frame).
    source_log : Path
        The catalogued log it was made from (odometry of dropped scans comes from here).
    """

    variant: Variant
    log: Path
    relations: Path
    source_log: Path


def default_cache_dir() -> Path:
    """``$XDG_CACHE_HOME/lineslam/variants``, else ``~/.cache/lineslam/variants``."""
    base = os.environ.get("XDG_CACHE_HOME")
    return (Path(base) if base else Path.home() / ".cache") / "lineslam" / "variants"


def _cache_key(source_sha256: str, transform: LogTransform, catalogued_name: bool) -> str:
    text = json.dumps(
        {
            "source": source_sha256,
            "version": MAKER_VERSION,
            "catalogued_name": catalogued_name,
            **transform.params(),
        },
        sort_keys=True,
    )
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def make_variant(
    variant: Variant,
    cache_dir: str | Path | None = None,
    *,
    root: str | Path | None = None,
    catalogued_name: bool = False,
) -> VariantFiles:
    """The variant's log and relations, generated into the cache unless already there.

    Parameters
    ----------
    variant
        A row of :data:`VARIANTS` (or any :class:`Variant`).
    cache_dir
        Folder of generated variants (default :func:`default_cache_dir`); one sub-folder per
        variant and source checksum.
    root
        Data root for the catalogued name (default: the catalogue's).
    catalogued_name
        Name the variant log as its source (the catalogue's facts then apply to it); by
        default it is named after the variant, a log the catalogue does not know.

    Raises
    ------
    DatasetError
        The dataset is unknown or missing.
    InputError
        It has no relations file.
    """
    resolved = resolve_log(variant.dataset, root=root)
    if resolved.relations is None:
        raise InputError(f"{variant.dataset}: no relations file, cannot score its variants")
    if variant.transform is None:
        return VariantFiles(variant, resolved.log, resolved.relations, resolved.log)
    transform = variant.transform
    cache = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    key = _cache_key(sha256_file(resolved.log), transform, catalogued_name)
    folder = cache / f"{variant.name}-{key}"
    if catalogued_name:
        log, relations = folder / resolved.log.name, folder / resolved.relations.name
    else:
        log, relations = folder / f"{variant.name}.clf", folder / f"{variant.name}.relations"
    if (folder / "variant.json").is_file():
        return VariantFiles(variant, log, relations, resolved.log)
    cache.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{variant.name}-", dir=cache))
    try:
        source = str(resolved.log)
        with (tmp / log.name).open("w", encoding="utf-8") as out:
            out.write(f"# lineslam variant {variant.name}: {json.dumps(transform.params())}\n")
            out.writelines(transform.rewrite(iter_text_lines(resolved.log), source))
        if type(transform).relations is LogTransform.relations:
            shutil.copyfile(resolved.relations, tmp / relations.name)
        else:
            rel = transform.relations(read_relations(resolved.relations))
            write_relations(tmp / relations.name, rel.t1, rel.t2, rel.poses)
        info = {**variant.params(), "source": source, "key": key, "log": log.name}
        (tmp / "variant.json").write_text(json.dumps(info, indent=1) + "\n", encoding="utf-8")
        try:
            tmp.rename(folder)
        except OSError:  # made meanwhile by another process: keep theirs
            if not (folder / "variant.json").is_file():
                raise
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return VariantFiles(variant, log, relations, resolved.log)


# ---------------------------------------------------------------------------------------------
# Scoring
# ---------------------------------------------------------------------------------------------
def fill_dropped_scans(trajectory: Trajectory, odometry: Trajectory) -> Trajectory:
    """A pose for every scan of ``odometry``: the trajectory's, else carried by odometry.

    Parameters
    ----------
    trajectory
        Estimated poses of (some of) the scans, matched to ``odometry`` by exact time stamp.
    odometry
        The odometry pose of every scan of the full log, in file order, in the trajectory's
        frame.

    Returns
    -------
    Trajectory
        ``odometry``'s time stamps; a scan in ``trajectory`` keeps its estimated pose, any
        other scan ``i`` gets ``pose(k) ∘ odom(k)⁻¹ ∘ odom(i)`` with ``k`` the last scan before it
        (file order) that the trajectory has, or the first one after it when there is none
        before.

    Raises
    ------
    EvaluationError
        No scan of the trajectory is in ``odometry``, or one of its time stamps is not.
    """
    idx, found = match_timestamps(trajectory.timestamps, odometry.timestamps, _STAMP_TOL_S)
    if not found.all():
        first = int(np.flatnonzero(~found)[0])
        raise EvaluationError(
            f"{int((~found).sum())} trajectory time stamps are not scans of the log "
            f"(e.g. {trajectory.timestamps[first]:.6f}): trajectory of another log?"
        )
    n = len(odometry)
    kept = np.zeros(n, dtype=bool)
    kept[idx] = True
    if not kept.any():
        raise EvaluationError("the trajectory has no pose to fill in from")
    estimate = np.empty((n, 3))
    estimate[idx] = trajectory.poses
    positions = np.arange(n)
    last = np.maximum.accumulate(np.where(kept, positions, -1))
    first_kept = int(np.flatnonzero(kept)[0])
    anchor = np.where(last >= 0, last, first_kept)
    dropped = ~kept
    if dropped.any():
        k = anchor[dropped]
        step = pose_between(odometry.poses[k], odometry.poses[dropped])
        estimate[dropped] = pose_compose(estimate[k], step)
    return Trajectory(odometry.timestamps.copy(), estimate)


@dataclass(frozen=True)
class RunScore:
    """Relations errors of a run and of the odometry of the same variant.

    Attributes
    ----------
    lineslam, odometry : RelationsMetric
        On every relation.
    lineslam_short, odometry_short : RelationsMetric or None
        On the relations with ``|t2 − t1| <`` :data:`SHORT_RELATION_S` (``None`` if there are
        none).
    frame : str
        Frame of the run's trajectory (as it reported it).
    odometry_frame : str
        Frame of the odometry baseline (that of the relations).
    scans_estimated, scans_filled : int
        Scans with an estimated pose, and dropped scans filled in by odometry.
    odometry_sign : str
        How the odometry was read (``"logged"`` or ``"velocity"``).
    """

    lineslam: RelationsMetric
    odometry: RelationsMetric
    lineslam_short: RelationsMetric | None
    odometry_short: RelationsMetric | None
    frame: str
    odometry_frame: str
    scans_estimated: int
    scans_filled: int
    odometry_sign: str

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary."""

        def m(metric: RelationsMetric | None) -> dict[str, Any] | None:
            return None if metric is None else metric.to_dict()

        return {
            "lineslam": m(self.lineslam),
            "odometry": m(self.odometry),
            "lineslam_short": m(self.lineslam_short),
            "odometry_short": m(self.odometry_short),
            "short_relation_s": SHORT_RELATION_S,
            "frame": self.frame,
            "odometry_frame": self.odometry_frame,
            "scans_estimated": self.scans_estimated,
            "scans_filled": self.scans_filled,
            "odometry_sign": self.odometry_sign,
        }


def score_run(
    trajectory: Trajectory, frame: str, files: VariantFiles, *, odometry_sign: str = "logged"
) -> RunScore:
    """Score a run's trajectory and the variant's odometry (module docstring).

    Parameters
    ----------
    trajectory
        The run's ``trajectory.tum``, as written.
    frame
        The frame the run reports (``summary.json`` ``"frame"``: ``"laser"`` or ``"base"``).
    files
        The variant it ran on.
    odometry_sign
        How the odometry of the fill-in and of the baseline is read (``"logged"`` or
        ``"velocity"``, :func:`slam.io.carmen.iter_log_scans`).

    Raises
    ------
    EvaluationError
        A relation time stamp that is not a scan of the source log.
    """
    if frame not in ("laser", "base"):
        raise ConfigError(f"frame must be laser or base, got {frame!r}")
    relations = read_relations(files.relations)

    def _odometry(log: Path, frame: str) -> Trajectory:
        return scan_trajectory(log, frame=frame, odometry_sign=odometry_sign)

    full_log_odometry = _odometry(files.source_log, frame)
    filled = fill_dropped_scans(trajectory, full_log_odometry)
    odometry_frame = (
        files.variant.transform.relations_frame if files.variant.transform is not None else "laser"
    )
    odometry = _odometry(files.log, odometry_frame)
    if len(odometry) < len(full_log_odometry):  # dropped scans: the source's odometry
        odometry = fill_dropped_scans(odometry, _odometry(files.source_log, odometry_frame))
    short = np.abs(relations.t2 - relations.t1) < SHORT_RELATION_S
    short_relations = relations.subset(short) if short.any() else None

    def metric(t: Trajectory, r: Relations | None) -> RelationsMetric | None:
        return None if r is None else relations_metric(t, r, max_unmatched_fraction=0.0)

    lineslam = relations_metric(filled, relations, max_unmatched_fraction=0.0)
    odo = relations_metric(odometry, relations, max_unmatched_fraction=0.0)
    return RunScore(
        lineslam=lineslam,
        odometry=odo,
        lineslam_short=metric(filled, short_relations),
        odometry_short=metric(odometry, short_relations),
        frame=frame,
        odometry_frame=odometry_frame,
        scans_estimated=len(trajectory),
        scans_filled=len(filled) - len(trajectory),
        odometry_sign=odometry_sign,
    )
