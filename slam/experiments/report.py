"""The comparison's report: one table of every variant, notes on its runs, figures.

:class:`CompareReport` holds the outcomes of :func:`slam.experiments.compare.run_compare`;
:func:`write_report` writes every variant's folder (``trajectory.tum``, ``map.json``,
``summary.json``), ``report.json`` (the table's rows, JSON-ready), ``report.md`` (the table,
a note per run that stopped early or is an EKF, the figures) and the figures
(:mod:`slam.plotting.compare`): trajectories over the map, error over the scans (relations
error where the source has relations, else position error after alignment), run time per
scan, and pose NEES over the scans with the 95 % interval of ``χ²₃``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slam import interrupts
from slam.evaluation import nees_bounds
from slam.experiments.linesim import world_and_trajectory
from slam.experiments.tasks import VariantOutcome
from slam.experiments.variants import DataSpec

__all__ = ["CompareReport", "write_report"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class CompareReport:
    """All variants of one comparison.

    Attributes
    ----------
    data : DataSpec
        The source every variant ran on.
    outcomes : list of VariantOutcome
        One per variant, in the order the variants were given.
    wall_time_s : float
        Wall time of all tasks (s).
    """

    data: DataSpec
    outcomes: list[VariantOutcome]
    wall_time_s: float

    def rows(self) -> list[dict[str, Any]]:
        """One row per variant for the table (JSON-ready)."""
        out = []
        for o in self.outcomes:
            est = o.estimate
            rt = est.scan_runtime_s
            out.append(
                {
                    "variant": o.variant.name,
                    "estimator": o.variant.estimator,
                    "weighted": o.variant.weighted,
                    **o.metrics,
                    "runtime_per_scan_ms_mean": float(1e3 * np.mean(rt)) if rt.size else None,
                    "runtime_per_scan_ms_max": float(1e3 * np.max(rt)) if rt.size else None,
                    "stopped_at_scan": est.stats.get("stopped_at_scan"),
                    "stop_reason": est.stats.get("stop_reason"),
                }
            )
        return out

    def to_dict(self) -> dict[str, Any]:
        """``report.json`` content."""
        return {
            "source": self.data.label,
            "kind": self.data.kind,
            "wall_time_s": self.wall_time_s,
            "variants": self.rows(),
        }

    def markdown_table(self) -> str:
        """The one comparison table (GitHub markdown)."""
        rows = self.rows()
        has_rel = any(r.get("rel_trans_mean_m") is not None for r in rows)
        has_gt = any(r.get("ate_rmse_m") is not None for r in rows)
        cols = ["variant"]
        if has_rel:
            cols += ["relations trans. (m)", "relations rot. (deg)", "relations used"]
        if has_gt:
            cols += ["ATE RMSE (m)", "mean NEES"]
        cols += ["landmarks", "time/scan (ms)", "total (s)", "note"]
        lines = ["| " + " | ".join(cols) + " |", "|---" + "|---:" * (len(cols) - 2) + "|---|"]
        for r in rows:
            note = ""
            if r.get("stopped_at_scan") is not None:
                note = f"stopped at scan {r['stopped_at_scan']}: {r['stop_reason']}"
            cells = [r["variant"]]
            if has_rel:
                cells += [
                    f"{_fmt(r.get('rel_trans_mean_m'), 3)} ± {_fmt(r.get('rel_trans_std_m'), 3)}",
                    f"{_fmt(r.get('rel_rot_mean_deg'), 2)} ± {_fmt(r.get('rel_rot_std_deg'), 2)}",
                    f"{r.get('relations_used', '–')}/{r.get('relations_total', '–')}",
                ]
            if has_gt:
                cells += [_fmt(r.get("ate_rmse_m"), 4), _fmt(r.get("nees_mean"), 2)]
            cells += [
                str(r.get("landmarks", "")),
                _fmt(r.get("runtime_per_scan_ms_mean"), 2),
                _fmt(r.get("runtime_s"), 1),
                note,
            ]
            lines.append("| " + " | ".join(cells) + " |")
        return "\n".join(lines)


def _fmt(value: Any, digits: int) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "–"
    return f"{value:.{digits}f}"


def write_report(report: CompareReport, out_dir: str | Path, figures: bool = True) -> Path:
    """Write every variant's folder, ``report.json``, ``report.md`` and the figures."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    for o in report.outcomes:
        interrupts.check()  # between files and figures (slam.interrupts)
        if o.estimate.result is not None and hasattr(o.estimate.result, "write"):
            o.estimate.result.write(out / o.variant.name)
    doc = report.to_dict()
    fig_names: list[str] = []
    if figures:
        fig_names = _figures(report, out)
    doc["figures"] = fig_names
    (out / "report.json").write_text(json.dumps(doc, indent=1), encoding="utf-8")
    md = [
        f"# Comparison on {report.data.label}",
        "",
        report.markdown_table(),
        "",
        f"Wall time {report.wall_time_s:.1f} s. EKF poses are filtered estimates (each uses the "
        "scans up to its own); graph poses are smoothed.",
        "",
    ]
    md += _run_notes(report)
    md += [f"![{name}]({name})" for name in fig_names]
    (out / "report.md").write_text("\n".join(md) + "\n", encoding="utf-8")
    return out


def _run_notes(report: CompareReport) -> list[str]:
    """Per EKF variant: ran to the end, or where and why it stopped; other variants if stopped.

    Other variants stop only on a time budget (``Variant.time_budget_s``).
    """
    lines: list[str] = []
    for o in report.outcomes:
        res = o.estimate.result
        stop = o.estimate.stats.get("stopped_at_scan")
        rt = np.asarray(o.estimate.scan_runtime_s)
        total = o.metrics.get("scans", rt.size)
        is_ekf = o.variant.estimator.startswith("ekf") and hasattr(res, "n_landmarks")
        if not is_ekf:
            if stop is not None:
                lines.append(
                    f"* {o.variant.name}: **stopped at scan {stop} of {total}**: "
                    f"{o.estimate.stats.get('stop_reason')}."
                )
            continue
        n_lm = np.asarray(res.n_landmarks)
        tail = rt[-max(1, rt.size // 20) :] if rt.size else rt
        size = (
            f"{int(n_lm[-1]) if n_lm.size else 0} landmarks at the end (peak "
            f"{int(n_lm.max()) if n_lm.size else 0}, state dimension {res.state_dim}), "
            f"{1e3 * float(np.mean(tail)) if tail.size else float('nan'):.1f} ms per scan over "
            f"the last 5 % of its scans (max {1e3 * float(np.max(rt)) if rt.size else 0:.0f} ms)"
        )
        if stop is None:
            lines.append(f"* {o.variant.name}: ran to the end ({total} scans); {size}.")
        else:
            lines.append(
                f"* {o.variant.name}: **stopped at scan {stop} of {total}**: "
                f"{o.estimate.stats.get('stop_reason')}; {size}."
            )
    head = "Runs (the EKF's update costs `O(n²)`, `n` its state dimension):"
    return [head, "", *lines, ""] if lines else []


def _figures(report: CompareReport, out: Path) -> list[str]:
    """Draw the report's figures into ``out``; their file names in the order drawn."""
    from slam.plotting.compare import (
        plot_errors_over_time,
        plot_nees_over_time,
        plot_runtime_per_scan,
        plot_trajectories,
    )

    names = []
    trajs = {o.variant.name: o.estimate.poses_world_laser for o in report.outcomes}
    segments: list[FloatArray] = []
    mapped = [o for o in report.outcomes if o.estimate.landmarks_r_alpha.shape[0] > 0]
    # the map of a variant that ran to the end (a time-budgeted one covers part of the log)
    mapped.sort(key=lambda o: o.estimate.stats.get("stopped_at_scan") is not None)
    if mapped and hasattr(mapped[0].estimate.result, "landmark_segments"):
        segments = list(mapped[0].estimate.result.landmark_segments)
    truth = None
    if report.data.kind == "sim":
        _, truth = world_and_trajectory(report.data.name, report.data.loops)
    title = "Trajectories over the map" + (f" ({mapped[0].variant.name})" if mapped else "")
    interrupts.check()
    plot_trajectories(trajs, out / "trajectories.png", segments, truth, title=title)
    names.append("trajectories.png")
    interrupts.check()
    errs = {o.variant.name: o.pos_err_m for o in report.outcomes if o.pos_err_m is not None}
    rel = {
        o.variant.name: (o.rel_scan, o.rel_err_m)
        for o in report.outcomes
        if o.rel_err_m is not None and o.rel_scan is not None
    }
    if rel:
        plot_errors_over_time(
            {k: np.maximum(v[1], 1e-4) for k, v in rel.items()},
            out / "error.png",
            ylabel="relation translation error (m)",
            title="Relations error over time (by the scan of each relation's first pose)",
            x={k: v[0] for k, v in rel.items()},
        )
        names.append("error.png")
    elif errs:
        plot_errors_over_time(errs, out / "error.png", ylabel="position error after alignment (m)")
        names.append("error.png")
    interrupts.check()
    runtimes = {o.variant.name: o.estimate.scan_runtime_s for o in report.outcomes}
    sizes = {
        o.variant.name: np.asarray(o.estimate.result.n_landmarks, dtype=float)
        for o in report.outcomes
        if hasattr(o.estimate.result, "n_landmarks") and o.estimate.landmarks_r_alpha.shape[0]
    }
    plot_runtime_per_scan(runtimes, out / "runtime.png", sizes or None)
    names.append("runtime.png")
    interrupts.check()
    nees = {o.variant.name: o.nees for o in report.outcomes if o.nees is not None}
    if nees:
        plot_nees_over_time(
            nees,
            nees_bounds(3, 1, 0.95),
            out / "nees.png",
            title="Pose NEES over time (one run; 95 % bounds of χ²₃)",
        )
        names.append("nees.png")
    return names
