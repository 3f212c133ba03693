"""The Kümmerle et al. relations metric, exactly as Cartographer's ``compute_relations_metrics``.

For every relation ``(t1, t2, expected)`` the trajectory's poses at ``t1`` and ``t2`` give

    error = (pose(t1)⁻¹ · pose(t2)) · expected⁻¹

(3-D rigid transforms; planar poses have ``z = 0``, and ``expected`` is built from
``x y z`` and ``roll pitch yaw`` as ``Rz(yaw)·Ry(pitch)·Rx(roll)``).  Reported, as Cartographer
prints them, the mean and the *sample* standard deviation (divisor ``n − 1``) of

* ``|t_error|`` (m) and ``|t_error|²`` (m²),
* ``|angle(R_error)|`` (deg) and its square (deg²),

with the rotation angle of ``R_error`` in ``[0°, 180°]``.

Time stamps are matched exactly (``|Δt| ≤ tolerance_s``, default 10 µs), never interpolated:
the relations of the public logs are stamped with the laser lines' own ``ipc_timestamp``.
Relations whose ``t1`` or ``t2`` is not a time stamp of the trajectory are counted
(``n_unmatched``) and left out; above ``max_unmatched_fraction`` (default 2 %) an
:class:`~slam.errors.EvaluationError` is raised, because that means a time stamp mistake (a
wrong field, rounding, sorting), not a few missing scans.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slam.errors import EvaluationError
from slam.evaluation.timestamps import check_unmatched_fraction, match_timestamps
from slam.geometry import pose_between
from slam.io.relations import Relations
from slam.io.trajectory import Trajectory

__all__ = [
    "MeanStd",
    "RelationsMetric",
    "match_timestamps",
    "relation_errors",
    "relations_metric",
    "relations_within",
]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class MeanStd:
    """Mean and sample standard deviation (divisor ``n − 1``; NaN for fewer than 2 values)."""

    mean: float
    std: float

    @classmethod
    def of(cls, values: FloatArray) -> MeanStd:
        """Cartographer's ``MeanAndStdDevString`` numbers for ``values``."""
        n = values.shape[0]
        if n == 0:
            return cls(math.nan, math.nan)
        mean = float(np.sum(values) / n)
        std = float(np.sqrt(np.sum((values - mean) ** 2) / (n - 1))) if n >= 2 else math.nan
        return cls(mean, std)

    def to_dict(self) -> dict[str, float]:
        """``{"mean": ..., "std": ...}``."""
        return {"mean": self.mean, "std": self.std}

    def __str__(self) -> str:
        return f"{self.mean:.5f} +/- {self.std:.5f}"


@dataclass(frozen=True)
class RelationsMetric:
    """Result of :func:`relations_metric` (serialises with :meth:`to_dict`).

    Attributes
    ----------
    n_relations, n_used, n_unmatched : int
        Relations in the file, used, and left out because a time stamp was not found.
    abs_trans_m, sqr_trans_m2, abs_rot_deg, sqr_rot_deg2 : MeanStd
        Cartographer's four lines.
    trans_errors_m, rot_errors_deg : ndarray
        Per used relation (not serialised).
    t1_s, t2_s : ndarray
        The used relations' time stamps, in the file's order (not serialised).
    """

    n_relations: int
    n_used: int
    n_unmatched: int
    abs_trans_m: MeanStd
    sqr_trans_m2: MeanStd
    abs_rot_deg: MeanStd
    sqr_rot_deg2: MeanStd
    tolerance_s: float
    trans_errors_m: FloatArray = field(repr=False)
    rot_errors_deg: FloatArray = field(repr=False)
    t1_s: FloatArray = field(repr=False, default_factory=lambda: np.zeros(0))
    t2_s: FloatArray = field(repr=False, default_factory=lambda: np.zeros(0))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (the per-relation errors are left out)."""
        return {
            "n_relations": self.n_relations,
            "n_used": self.n_used,
            "n_unmatched": self.n_unmatched,
            "abs_trans_m": self.abs_trans_m.to_dict(),
            "sqr_trans_m2": self.sqr_trans_m2.to_dict(),
            "abs_rot_deg": self.abs_rot_deg.to_dict(),
            "sqr_rot_deg2": self.sqr_rot_deg2.to_dict(),
            "tolerance_s": self.tolerance_s,
        }

    def cartographer_report(self) -> str:
        """The four lines as ``compute_relations_metrics`` prints them."""
        return (
            f"Abs translational error {self.abs_trans_m} m\n"
            f"Sqr translational error {self.sqr_trans_m2} m^2\n"
            f"Abs rotational error {self.abs_rot_deg} deg\n"
            f"Sqr rotational error {self.sqr_rot_deg2} deg^2\n"
        )


def _rot_z(angle: FloatArray) -> FloatArray:
    c, s = np.cos(angle), np.sin(angle)
    out = np.zeros(angle.shape + (3, 3))
    out[..., 0, 0], out[..., 0, 1], out[..., 1, 0], out[..., 1, 1] = c, -s, s, c
    out[..., 2, 2] = 1.0
    return out


def _rot_rpy(roll: FloatArray, pitch: FloatArray, yaw: FloatArray) -> FloatArray:
    cr, sr = np.cos(roll), np.sin(roll)
    cp, sp = np.cos(pitch), np.sin(pitch)
    rx = np.zeros(roll.shape + (3, 3))
    rx[..., 0, 0] = 1.0
    rx[..., 1, 1], rx[..., 1, 2], rx[..., 2, 1], rx[..., 2, 2] = cr, -sr, sr, cr
    ry = np.zeros(roll.shape + (3, 3))
    ry[..., 1, 1] = 1.0
    ry[..., 0, 0], ry[..., 0, 2], ry[..., 2, 0], ry[..., 2, 2] = cp, sp, -sp, cp
    return _rot_z(yaw) @ ry @ rx


def relation_errors(
    pose_1: FloatArray, pose_2: FloatArray, relations: Relations
) -> tuple[FloatArray, FloatArray]:
    """``|t|`` (m) and rotation angle (rad, in [0, π]) of ``(pose_1⁻¹·pose_2)·expected⁻¹``.

    Parameters
    ----------
    pose_1, pose_2 : ndarray, shape (m, 3)
        Planar poses at ``t1`` and ``t2`` of each relation.
    relations : Relations
        The ``m`` expected relative poses.
    """
    rel = pose_between(pose_1, pose_2)
    r_rel = _rot_z(rel[:, 2])
    t_rel = np.column_stack([rel[:, 0], rel[:, 1], np.zeros(rel.shape[0])])
    r_exp = _rot_rpy(relations.roll, relations.pitch, relations.poses[:, 2])
    t_exp = np.column_stack([relations.poses[:, 0], relations.poses[:, 1], relations.z])
    r_err = r_rel @ np.swapaxes(r_exp, -1, -2)
    t_err = t_rel - np.einsum("mij,mj->mi", r_err, t_exp)
    trans = np.sqrt(np.sum(t_err**2, axis=1))
    vee = np.stack(
        [
            r_err[:, 2, 1] - r_err[:, 1, 2],
            r_err[:, 0, 2] - r_err[:, 2, 0],
            r_err[:, 1, 0] - r_err[:, 0, 1],
        ],
        axis=1,
    )
    sin_angle = 0.5 * np.sqrt(np.sum(vee**2, axis=1))
    cos_angle = 0.5 * (np.trace(r_err, axis1=1, axis2=2) - 1.0)
    return trans, np.arctan2(sin_angle, cos_angle)


def relations_within(
    relations: Relations, timestamps: FloatArray, *, tolerance_s: float = 1e-5
) -> Relations:
    """The relations whose ``t1`` and ``t2`` are both time stamps in ``timestamps``.

    For runs over part of a log (``--max-scans``, excerpts in tests): the relations outside
    the run are left out *deliberately* here, so that :func:`relations_metric`'s unmatched
    count keeps meaning a time stamp mistake.
    """
    _, found1 = match_timestamps(relations.t1, timestamps, tolerance_s)
    _, found2 = match_timestamps(relations.t2, timestamps, tolerance_s)
    return relations.subset(found1 & found2)


def relations_metric(
    trajectory: Trajectory,
    relations: Relations,
    *,
    tolerance_s: float = 1e-5,
    max_unmatched_fraction: float = 0.02,
) -> RelationsMetric:
    """Evaluate a trajectory against relations (see the module docstring).

    Parameters
    ----------
    trajectory
        Poses at time stamps (any order).
    relations
        Ground-truth relative poses, e.g. from :func:`slam.io.relations.read_relations`.
    tolerance_s
        Largest ``|Δt|`` for a relation time stamp to match a trajectory time stamp.
    max_unmatched_fraction
        Raise if more relations than this fraction have a time stamp that is not found.

    Raises
    ------
    EvaluationError
        Too many unmatched relations, or none left.
    ConfigError
        ``tolerance_s`` negative or NaN, ``max_unmatched_fraction`` outside [0, 1] or NaN.
    """
    check_unmatched_fraction(max_unmatched_fraction)
    if len(relations) == 0:
        raise EvaluationError("no relations to evaluate")
    i1, ok1 = match_timestamps(relations.t1, trajectory.timestamps, tolerance_s)
    i2, ok2 = match_timestamps(relations.t2, trajectory.timestamps, tolerance_s)
    used = ok1 & ok2
    n = len(relations)
    n_unmatched = int(n - used.sum())
    if n_unmatched > max_unmatched_fraction * n or not used.any():
        first = int(np.flatnonzero(~used)[0])
        raise EvaluationError(
            f"{n_unmatched} of {n} relations have a time stamp that is not in the trajectory "
            f"(|dt| > {tolerance_s:g} s; allowed {max_unmatched_fraction:.0%}); e.g. relation "
            f"{first} ({relations.t1[first]:.6f}, {relations.t2[first]:.6f}): a time stamp "
            "mistake (wrong field, rounding, or trajectory of another log)?"
        )
    sub = Relations(
        relations.t1[used],
        relations.t2[used],
        relations.poses[used],
        relations.z[used],
        relations.roll[used],
        relations.pitch[used],
        relations.line_numbers[used],
    )
    trans, angle = relation_errors(trajectory.poses[i1[used]], trajectory.poses[i2[used]], sub)
    rot_deg = np.degrees(angle)
    return RelationsMetric(
        n_relations=n,
        n_used=int(used.sum()),
        n_unmatched=n_unmatched,
        abs_trans_m=MeanStd.of(trans),
        sqr_trans_m2=MeanStd.of(trans**2),
        abs_rot_deg=MeanStd.of(rot_deg),
        sqr_rot_deg2=MeanStd.of(rot_deg**2),
        tolerance_s=tolerance_s,
        trans_errors_m=trans,
        rot_errors_deg=rot_deg,
        t1_s=sub.t1,
        t2_s=sub.t2,
    )
