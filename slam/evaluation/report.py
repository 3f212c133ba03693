"""Evaluate a results folder: the metrics of ``lineslam evaluate`` and ``metrics.json``.

Main entry point::

    report = evaluate_results(results, relations=rel, ground_truth=gt, rpe_deltas_m=(1.0,))
    report.to_dict()       # metrics.json
    report.format_table()  # what the CLI prints
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slam.errors import EvaluationError
from slam.evaluation.ate import AteResult, ate
from slam.evaluation.nees import JointCovariance, NeesResult, pose_nees
from slam.evaluation.odometry_bias import FrameOffset, relations_frame_offset
from slam.evaluation.reference_noise import RelationNoise, relation_noise
from slam.evaluation.relations_metric import RelationsMetric, relations_metric, relations_within
from slam.evaluation.relations_nees import (
    RelationCovariances,
    RelationErrorDraws,
    RelationsNees,
    relations_nees,
)
from slam.evaluation.rpe import RpeResult, rpe
from slam.io.relations import Relations
from slam.io.results import Results
from slam.io.trajectory import Trajectory

__all__ = ["EvaluationReport", "evaluate_results"]

#: The relations the frame offset is fitted to are shorter than this (s).
FRAME_MAX_GAP_S = 10.0
#: Bootstrap resamples of the frame offset's spread (seed 0).
FRAME_RESAMPLES = 50

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class EvaluationReport:
    """Everything ``lineslam evaluate`` computed for one trajectory."""

    n_poses: int
    frame: str
    relations: RelationsMetric | None = None
    ate: AteResult | None = None
    rpe: tuple[RpeResult, ...] = ()
    nees: NeesResult | None = None
    sources: dict[str, str] = field(default_factory=dict)
    relations_inside_run: tuple[int, int] | None = None
    relations_nees: RelationsNees | None = None
    relations_noise: RelationNoise | None = None
    relations_nees_with_relations_noise: RelationsNees | None = None
    relations_noise_skipped: str | None = None
    #: Where the relations' frame sits in the trajectory's (:func:`slam.evaluation.
    #: odometry_bias.relations_frame_offset`), or why it was not fitted.
    relations_frame: FrameOffset | None = None
    relations_frame_skipped: str | None = None
    #: How far passes along the same walls disagree (:func:`slam.line_slam.passes.pass_consistency`,
    #: as its ``to_dict``), when the results folder has a ``graph.g2o``.
    walls_between_passes: dict[str, Any] | None = None

    def relation_rows(self) -> dict[str, FloatArray] | None:
        """Every relation used, one entry per column (``relation_errors.csv``); None without.

        Columns: ``t1_s``, ``t2_s``, ``trans_error_m`` and ``rot_error_deg`` (the relations
        metric's), ``nees`` and ``nees_with_relations_noise`` (NaN where not computed).
        """
        rel = self.relations
        if rel is None:
            return None
        rows: dict[str, FloatArray] = {
            "t1_s": rel.t1_s,
            "t2_s": rel.t2_s,
            "trans_error_m": rel.trans_errors_m,
            "rot_error_deg": rel.rot_errors_deg,
        }
        for name, q in (
            ("nees", self.relations_nees),
            ("nees_with_relations_noise", self.relations_nees_with_relations_noise),
        ):
            column = np.full(rel.t1_s.shape, np.nan)
            if q is not None:
                if not (np.array_equal(q.t1_s, rel.t1_s) and np.array_equal(q.t2_s, rel.t2_s)):
                    raise EvaluationError(
                        "the relations NEES was computed on other relations than the metric"
                    )
                column = q.values
            rows[name] = column
        return rows

    def to_dict(self) -> dict[str, Any]:
        """The content of ``metrics.json``."""
        out: dict[str, Any] = {"n_poses": self.n_poses, "frame": self.frame, **self.sources}
        if self.relations is not None:
            out["relations"] = self.relations.to_dict()
        if self.relations_inside_run is not None:
            inside, total = self.relations_inside_run
            out["partial_run"] = {"relations_inside_run": inside, "relations_in_file": total}
        if self.ate is not None:
            out["ate"] = self.ate.to_dict()
        if self.rpe:
            out["rpe"] = [r.to_dict() for r in self.rpe]
        if self.nees is not None:
            out["nees"] = self.nees.to_dict()
        if self.relations_nees is not None:
            out["relations_nees"] = self.relations_nees.to_dict()
        if self.relations_noise is not None:
            out["relations_noise"] = self.relations_noise.to_dict()
        elif self.relations_noise_skipped is not None:
            out["relations_noise"] = {"skipped": self.relations_noise_skipped}
        if self.relations_nees_with_relations_noise is not None:
            out["relations_nees_with_relations_noise"] = (
                self.relations_nees_with_relations_noise.to_dict()
            )
        bracket = self.relations_nees_bracket()
        if bracket is not None:
            out["relations_nees_bracket"] = bracket
        if self.relations_frame is not None:
            f = self.relations_frame
            out["relations_frame"] = {
                "x_m": f.x_m,
                "y_m": f.y_m,
                "sd_x_m": f.sd_x_m,
                "sd_y_m": f.sd_y_m,
                "relations": f.relations,
                "max_gap_s": FRAME_MAX_GAP_S,
                "bootstrap_resamples": FRAME_RESAMPLES,
            }
        elif self.relations_frame_skipped is not None:
            out["relations_frame"] = {"skipped": self.relations_frame_skipped}
        if self.walls_between_passes is not None:
            out["walls_between_passes"] = dict(self.walls_between_passes)
        return out

    def relations_nees_bracket(self) -> dict[str, Any] | None:
        """The run's relations NEES bracketed, when both NEES were computed.

        The plain relations NEES counts the relations' own scatter as the run's error (an
        upper bound on the run's NEES), the one with the three-cornered hat's scatter added
        counts up to the run's own variance as the relations' (a lower bound;
        :mod:`slam.evaluation.reference_noise`).  ``verdict``: ``"over-confident"`` when even
        the lower bound lies above its one-run interval, ``"under-confident"`` when even the
        upper bound lies below its own, else ``"consistent"`` (the data cannot tell the run
        inconsistent).
        """
        upper, lower = self.relations_nees, self.relations_nees_with_relations_noise
        if upper is None or lower is None:
            return None
        if lower.mean > lower.interval[1]:
            verdict = "over-confident"
        elif upper.mean < upper.interval[0]:
            verdict = "under-confident"
        else:
            verdict = "consistent"
        return {"lower": lower.mean, "upper": upper.mean, "verdict": verdict}

    def format_table(self) -> str:
        """A plain-text table of the metrics."""
        rows: list[tuple[str, str]] = [("poses", f"{self.n_poses} ({self.frame} frame)")]
        if self.relations is not None:
            m = self.relations
            if self.relations_inside_run is not None:
                inside, total = self.relations_inside_run
                rows.append(
                    ("partial run", f"{inside} of the file's {total} relations lie inside it")
                )
            rows += [
                ("relations used", f"{m.n_used}/{m.n_relations} (unmatched {m.n_unmatched})"),
                ("abs trans (m)", str(m.abs_trans_m)),
                ("sqr trans (m^2)", str(m.sqr_trans_m2)),
                ("abs rot (deg)", str(m.abs_rot_deg)),
                ("sqr rot (deg^2)", str(m.sqr_rot_deg2)),
            ]
        if self.relations_frame is not None:
            f = self.relations_frame
            rows.append(
                (
                    "relations' frame",
                    f"x {f.x_m:+.4f} m (sd {f.sd_x_m:.4f}), y {f.y_m:+.4f} m (sd {f.sd_y_m:.4f}) "
                    f"in the {self.frame} frame (from the turns of {f.relations} relations "
                    f"< {FRAME_MAX_GAP_S:g} s; 0: they relate that frame)",
                )
            )
        if self.ate is not None:
            a = self.ate
            rows += [
                ("ATE rmse (m)", f"{a.translation_m.rmse:.5f} (n={a.translation_m.n})"),
                ("ATE mean/max (m)", f"{a.translation_m.mean:.5f} / {a.translation_m.max:.5f}"),
                ("ATE rot rmse (deg)", f"{a.rotation_deg.rmse:.5f}"),
            ]
        for r in self.rpe:
            rows += [
                (
                    f"RPE {r.delta_m:g} m trans rmse (m)",
                    f"{r.translation_m.rmse:.5f} (pairs {r.translation_m.n})",
                ),
                (f"RPE {r.delta_m:g} m rot rmse (deg)", f"{r.rotation_deg.rmse:.5f}"),
            ]
        if self.nees is not None:
            s = self.nees
            verdict = "consistent" if s.consistent else "NOT consistent"
            if s.one_run is None or s.one_run_mean is None:
                rows.append(
                    (
                        "pose NEES mean",
                        f"{s.mean:.3f} in [{s.lower:.3f}, {s.upper:.3f}] (poses taken as "
                        f"independent): {verdict}",
                    )
                )
            else:
                b = s.one_run
                of = "" if b.n == s.n else f" (over {b.n} of the {s.n} poses)"
                rows += [
                    (
                        "pose NEES mean",
                        f"{s.one_run_mean:.3f} in [{b.lower:.3f}, {b.upper:.3f}] for one run"
                        f"{of}: {verdict}",
                    ),
                    (
                        "  poses correlated",
                        f"{b.effective_dof:.1f} effective dof (independent poses: {3 * b.n}, "
                        f"mean in [{s.lower:.3f}, {s.upper:.3f}])",
                    ),
                ]
        if self.relations_nees is not None:
            q = self.relations_nees
            verdict = "consistent" if q.consistent else "NOT consistent"
            rows += [
                (
                    "relations NEES mean",
                    f"{q.mean:.3f} in {_interval_text(q)}: {verdict} (n={q.n})",
                ),
                (
                    "relations NEES median",
                    f"{q.median:.3f} (chi2_3: 2.366); translation {q.mean_translation:.3f} "
                    f"(2), heading {q.mean_rotation:.3f} (1)",
                ),
                (
                    "relations inside 95%",
                    f"{q.fraction_inside_95:.3f} (NEES <= {q.single_bound_95:.2f}; 0.95 expected)",
                ),
                (
                    "relations NEES by gap",
                    _by_gap_text(q),
                ),
            ]
        if self.relations_noise is not None:
            rn = self.relations_noise.to_dict()

            def cm_mrad(v: list[float]) -> str:
                return f"{100 * v[0]:.2f} / {100 * v[1]:.2f} cm, {1000 * v[2]:.1f} mrad"

            rows += [
                (
                    "relations' own RMS",
                    f"{cm_mrad(rn['rms_relations_xy_theta'])} (x / y, heading; three-cornered "
                    f"hat on {rn['n']} relations < {rn['max_gap_s']:g} s"
                    f"{' between keyframes' if rn['keyframes_only'] else ''}; the odometry "
                    f"coincides with {rn['odometry_coincides']})",
                ),
                (
                    "  run / odometry RMS",
                    f"{cm_mrad(rn['rms_run_xy_theta'])} / {cm_mrad(rn['rms_odometry_xy_theta'])}",
                ),
            ]
        if self.relations_noise_skipped is not None:
            rows.append(("relations' own RMS", f"not estimated: {self.relations_noise_skipped}"))
        if self.relations_nees_with_relations_noise is not None:
            q = self.relations_nees_with_relations_noise
            lo, hi = q.interval
            where = "inside" if lo <= q.mean <= hi else ("below" if q.mean < lo else "above")
            rows += [
                (
                    "relations NEES + relations' own",
                    f"{q.mean:.3f}, {where} {_interval_text(q)}; inside 95% "
                    f"{q.fraction_inside_95:.3f}",
                ),
                (
                    "  by gap",
                    _by_gap_text(q),
                ),
            ]
        bracket = self.relations_nees_bracket()
        if bracket is not None:
            rows.append(
                (
                    "relations NEES bracket",
                    f"[{bracket['lower']:.3f}, {bracket['upper']:.3f}] (with the relations' own "
                    f"scatter, without): {_BRACKET_TEXT[bracket['verdict']]}",
                )
            )
        w = self.walls_between_passes
        if w is not None and w.get("pairs"):
            rows.append(
                (
                    "walls between passes",
                    f"median t {w['median_ratio']:.2f} x chi2_2's (angle "
                    f"{w['median_ratio_angle']:.2f} x chi2_1's; about 1 where the line factors "
                    f"hold), {w['pairs']} pairs of "
                    f"passes {w['gap_s']:g} s apart on {w['landmarks']} walls, "
                    f"{w['fraction_beyond_95']:.2f} beyond chi2_2's 95 %",
                )
            )
            if w.get("median_ratio_with_pass_error") is not None:
                rows.append(
                    (
                        "  with the pass error",
                        f"median t {w['median_ratio_with_pass_error']:.2f} x chi2_2's, "
                        f"{w['fraction_beyond_95_with_pass_error']:.2f} beyond its 95 % (the "
                        f"error each pass shares, estimated from these pairs: "
                        f"{1e3 * w['pass_error_sigma_offset_m']:.1f} mm, "
                        f"{1e3 * w['pass_error_sigma_angle_rad']:.1f} mrad)",
                    )
                )
        width = max(len(k) for k, _ in rows)
        return "\n".join(f"{k:<{width}}  {v}" for k, v in rows)


_BRACKET_TEXT = {
    "consistent": "consistent as far as the relations tell (their interval meets the bracket)",
    "over-confident": "over-confident (even the lower bound lies above its interval)",
    "under-confident": "under-confident (even the upper bound lies below its interval)",
}


def _interval_text(q: RelationsNees) -> str:
    """The interval the verdict uses: one run's (with its effective dof) or independent ones'."""
    if q.one_run is None:
        return f"[{q.lower:.3f}, {q.upper:.3f}] (relations taken as independent)"
    b = q.one_run
    return (
        f"[{b.lower:.3f}, {b.upper:.3f}] for one run ({b.effective_dof:.0f} effective dof; "
        f"independent: [{q.lower:.3f}, {q.upper:.3f}])"
    )


def _by_gap_text(q: RelationsNees) -> str:
    """Mean NEES per time gap of the non-empty gap classes, as the table prints it."""
    return "; ".join(
        f"{_gap_label(g['gap_s'])}: {g['mean']:.2f} (n={g['n']})" for g in q.by_gap() if g["n"]
    )


def _gap_label(gap: list[float | None]) -> str:
    lo, hi = gap
    return f">= {lo:g} s" if hi is None else f"{lo:g}-{hi:g} s"


def evaluate_results(
    results: Results | Trajectory,
    *,
    relations: Relations | None = None,
    ground_truth: Trajectory | None = None,
    rpe_deltas_m: Sequence[float] = (1.0,),
    tolerance_s: float = 1e-5,
    max_unmatched_fraction: float = 0.02,
    sources: dict[str, str] | None = None,
    partial: bool | None = None,
    relative_covariances: RelationCovariances | None = None,
    odometry: Trajectory | None = None,
    keyframe_timestamps: FloatArray | None = None,
    joint_covariance: JointCovariance | None = None,
    relation_error_draws: RelationErrorDraws | None = None,
) -> EvaluationReport:
    """Relations metric (with ``relations``), ATE, RPE and NEES (with ``ground_truth``).

    With relations, also where the frame they relate sits in the trajectory's
    (:func:`slam.evaluation.odometry_bias.relations_frame_offset`, from the turns of the
    relations shorter than :data:`FRAME_MAX_GAP_S`): about zero when they relate the frame
    the run reports.

    NEES is computed when ``results`` carries pose covariances and ground truth is given; the
    relations NEES (:mod:`slam.evaluation.relations_nees`) when relations and
    ``relative_covariances`` (covariances of relative poses between time stamps) are given;
    with the log's ``odometry`` too (in the relations' frame), the relations' own scatter
    (:mod:`slam.evaluation.reference_noise`, on the relations between two of
    ``keyframe_timestamps`` when given) and the relations NEES with it added.  With
    ``joint_covariance`` (the joint covariance of poses at given time stamps) the pose NEES
    is also tested against the interval of one run's mean
    (:func:`slam.evaluation.nees.correlated_nees_bounds`), and with ``relation_error_draws``
    (joint draws of the relations' errors under the run's model) the relations NEES too
    (:mod:`slam.evaluation.relations_nees`).

    A run over part of a log (``partial``; default: what the results' ``summary.json`` says,
    ``"partial": true`` for ``--max-scans`` runs) is scored on the relations whose two time
    stamps both lie inside it (:func:`slam.evaluation.relations_metric.relations_within`);
    the report says how many of the file's that is.  A complete run keeps the strict check
    (unmatched relations mean a time stamp mistake).
    """
    if relations is None and ground_truth is None:
        raise EvaluationError("nothing to evaluate against: give relations and/or ground truth")
    if isinstance(results, Results):
        trajectory, frame, cov = results.trajectory, results.frame, results.covariances
    else:
        trajectory, frame, cov = results, "laser", None
    tol, frac = tolerance_s, max_unmatched_fraction
    if partial is None:
        partial = isinstance(results, Results) and bool(results.summary.get("partial", False))
    rel = None
    inside_run: tuple[int, int] | None = None
    if relations is not None and partial:
        total = len(relations)
        relations = relations_within(relations, trajectory.timestamps, tolerance_s=tol)
        inside_run = (len(relations), total)
        if len(relations) == 0:
            raise EvaluationError(
                f"none of the {total} relations has both time stamps inside the partial run "
                f"({len(trajectory)} poses): run over more of the log"
            )
    rel_nees = rel_nees_ref = None
    rel_noise: RelationNoise | None = None
    noise_skipped: str | None = None
    frame_offset: FrameOffset | None = None
    frame_skipped: str | None = None
    if relations is not None:
        rel = relations_metric(trajectory, relations, tolerance_s=tol, max_unmatched_fraction=frac)
        try:
            frame_offset = relations_frame_offset(
                trajectory.timestamps, trajectory.poses, relations.t1, relations.t2,
                relations.poses, short_s=FRAME_MAX_GAP_S, resamples=FRAME_RESAMPLES,
                tolerance_s=tol,
            )  # fmt: skip
        except EvaluationError as exc:  # too few short relations: the rest stands
            frame_skipped = str(exc)
        if relative_covariances is not None:
            rel_nees = relations_nees(
                trajectory,
                relations,
                relative_covariances,
                tolerance_s=tol,
                error_draws=relation_error_draws,
            )
            if odometry is not None:
                try:
                    rel_noise = relation_noise(
                        trajectory,
                        odometry,
                        relations,
                        tolerance_s=tol,
                        keyframe_timestamps=keyframe_timestamps,
                    )
                except EvaluationError as exc:  # too few short relations: the rest stands
                    noise_skipped = str(exc)
            if rel_noise is not None:
                rel_nees_ref = relations_nees(
                    trajectory,
                    relations,
                    relative_covariances,
                    tolerance_s=tol,
                    error_draws=relation_error_draws,
                    relations_cov=rel_noise.covariance,
                )
    ate_result = nees_result = None
    rpe_results: tuple[RpeResult, ...] = ()
    if ground_truth is not None:
        ate_result = ate(trajectory, ground_truth, tolerance_s=tol, max_unmatched_fraction=frac)
        rpe_results = tuple(
            rpe(trajectory, ground_truth, d, tolerance_s=tol, max_unmatched_fraction=frac)
            for d in rpe_deltas_m
        )
        if cov is not None:
            nees_result = pose_nees(
                trajectory,
                cov,
                ground_truth,
                tolerance_s=tol,
                max_unmatched_fraction=frac,
                joint_covariance=joint_covariance,
            )
    return EvaluationReport(
        n_poses=len(trajectory),
        frame=frame,
        relations=rel,
        ate=ate_result,
        rpe=rpe_results,
        nees=nees_result,
        sources=dict(sources or {}),
        relations_inside_run=inside_run,
        relations_nees=rel_nees,
        relations_noise=rel_noise,
        relations_nees_with_relations_noise=rel_nees_ref,
        relations_noise_skipped=noise_skipped,
        relations_frame=frame_offset,
        relations_frame_skipped=frame_skipped,
    )
