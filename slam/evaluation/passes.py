"""Between-pass consistency of the walls: do separate passes along a wall agree as modelled.

A line factor's covariance treats every observation of a wall as independent of the others.
If the wall's departures from a straight line (or anything else shared by observations from
nearby poses) make the observations of one *pass* along it err together, a pass averages
them far less than the factors say, and two passes disagree by more than the factors' own
covariances allow.  Loop closures join such passes, so this is where a run's relative poses
across loops would be over-confident.

Each landmark's factors are split into passes: consecutive observations (in time) less than
``gap_s`` apart are one pass.  Each factor is linearised at the estimate with the run's robust
kernel (its IRLS weight included), in the landmark's anchored chart, ``A_l δ ≈ b``
(:func:`slam.graph.factors.linearize_line_factors`), so a pass ``p`` with factors ``i`` sees
the landmark moved by

``m_p = (Σ A_lᵢᵀ A_lᵢ)⁻¹ Σ A_lᵢᵀ bᵢ``,   ``C_p = (Σ A_lᵢᵀ A_lᵢ)⁻¹``

with the poses held at their estimates.  For two passes of one landmark, ``d = m_p − m_q``
and ``t = dᵀ (C_p + C_q)⁻¹ d``; ``t_angle = d_φ² / (C_p + C_q)_φφ`` is its angle part.  With
the poses and landmarks at the truth and the factors' covariances true, ``t`` is χ²₂ and
``t_angle`` χ²₁ (``tests/test_passes.py``).  The report gives their medians over all pairs of
passes of every landmark, each divided by its χ² median, and the fraction of pairs beyond
χ²₂'s 95 % quantile.

At a run's estimate the poses have been fitted to these same factors, loop closures
included, which pulls the passes together: on simulated walls, where the factors' model is
true, the ratio comes out below 1 (the demo: 0.42 with ``gap_s = 30``).  Compare runs with
it, not with 1.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slam.errors import EvaluationError
from slam.graph.factors import linearize_line_factors, sqrt_information_2x2
from slam.graph.problem import LineGraph
from slam.graph.relative import line_graph_from_file
from slam.io.g2o import read_line_graph_g2o

__all__ = ["PassConsistency", "pass_consistency", "pass_consistency_of_results"]

FloatArray = NDArray[np.float64]

CHI2_2_MEDIAN = 2.0 * math.log(2.0)
"""Median of χ²₂."""
CHI2_1_MEDIAN = 0.454936423119572
"""Median of χ²₁."""
CHI2_2_95 = -2.0 * math.log(0.05)
"""95 % quantile of χ²₂."""


@dataclass(frozen=True)
class PassConsistency:
    """How far passes along the same walls agree (module docstring).

    Attributes
    ----------
    gap_s : float
        Observations of a landmark this far apart in time (s) or more start a new pass.
    landmarks : int
        Landmarks with at least two passes of ``min_observations``.
    pairs : int
        Pairs of passes compared.
    median_ratio : float
        Median of ``t`` over the pairs divided by the χ²₂ median (1 when the model holds).
    median_ratio_angle : float
        The same for the angle alone (χ²₁).
    fraction_beyond_95 : float
        Pairs with ``t`` above χ²₂'s 95 % quantile (0.05 expected).
    """

    gap_s: float
    landmarks: int
    pairs: int
    median_ratio: float
    median_ratio_angle: float
    fraction_beyond_95: float

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return asdict(self)


def pass_consistency(
    graph: LineGraph,
    pose_timestamps: ArrayLike,
    robust_kernel: tuple[str, float] | None = None,
    gap_s: float = 30.0,
    min_observations: int = 3,
) -> PassConsistency:
    """Between-pass consistency of a graph's landmarks at its estimate (module docstring).

    Parameters
    ----------
    graph : LineGraph
        Poses, landmarks and line factors at the estimate (e.g. a ``graph.g2o`` read back by
        :func:`slam.graph.relative.line_graph_from_file`).
    pose_timestamps : array_like, shape (n_poses,)
        Time (s) of each pose.
    robust_kernel : (str, float), optional
        The run's kernel on the line factors and its width (default none).
    gap_s : float
        Time (s) between two observations of a landmark from which they are separate passes.
    min_observations : int
        Least number of factors in a pass for it to be compared.

    Raises
    ------
    EvaluationError
        ``gap_s`` is not a positive number, or the time stamps are not one per pose.
    """
    if not (math.isfinite(gap_s) and gap_s > 0.0):
        raise EvaluationError(f"gap_s must be a positive number of seconds, got {gap_s!r}")
    stamps = np.asarray(pose_timestamps, dtype=float).reshape(-1)
    g = graph
    if stamps.shape[0] != g.n_poses:
        raise EvaluationError(f"{stamps.shape[0]} time stamps for {g.n_poses} poses")
    n = g.n_line_factors
    kernel, width = robust_kernel or ("none", 1.0)
    if n == 0:
        return PassConsistency(gap_s, 0, 0, math.nan, math.nan, math.nan)
    lm = g.factor_landmark[:n]
    lin = linearize_line_factors(
        g.poses[g.factor_pose[:n]],
        g.landmarks[lm],
        g.anchors[lm],
        g.factor_z[:n],
        sqrt_information_2x2(g.factor_cov[:n]),
        kernel,  # type: ignore[arg-type]
        width,
    )
    A = lin.A_landmark
    info = np.swapaxes(A, 1, 2) @ A
    rhs = np.einsum("fji,fj->fi", A, lin.b)
    t_of = stamps[g.factor_pose[:n]]
    order = np.lexsort((t_of, lm))
    lm_sorted, t_sorted = lm[order], t_of[order]
    # a new pass where the landmark changes or its observations are gap_s apart
    start = np.r_[True, (lm_sorted[1:] != lm_sorted[:-1]) | (np.diff(t_sorted) >= gap_s)]
    pass_id = np.cumsum(start) - 1
    n_pass = int(pass_id[-1]) + 1
    count = np.bincount(pass_id, minlength=n_pass)
    I_p = np.zeros((n_pass, 2, 2))
    r_p = np.zeros((n_pass, 2))
    np.add.at(I_p, pass_id, info[order])
    np.add.at(r_p, pass_id, rhs[order])
    pass_lm = lm_sorted[start]
    keep = count >= min_observations
    keep &= np.linalg.det(I_p) > 0.0
    C_p = np.full_like(I_p, np.nan)
    C_p[keep] = np.linalg.inv(I_p[keep])
    m_p = np.einsum("pij,pj->pi", C_p, r_p)
    t_all: list[FloatArray] = []
    t_angle: list[FloatArray] = []
    n_landmarks = 0
    kept = np.flatnonzero(keep)
    bounds = np.flatnonzero(np.r_[True, pass_lm[kept][1:] != pass_lm[kept][:-1]])
    for group in np.split(kept, bounds[1:]):
        if group.size < 2:
            continue
        n_landmarks += 1
        a, b = np.triu_indices(group.size, 1)
        d = m_p[group[a]] - m_p[group[b]]
        S = C_p[group[a]] + C_p[group[b]]
        t_all.append(np.einsum("ki,kij,kj->k", d, np.linalg.inv(S), d))
        t_angle.append(d[:, 1] ** 2 / S[:, 1, 1])
    if not t_all:
        return PassConsistency(gap_s, 0, 0, math.nan, math.nan, math.nan)
    t = np.concatenate(t_all)
    ta = np.concatenate(t_angle)
    return PassConsistency(
        gap_s=gap_s,
        landmarks=n_landmarks,
        pairs=int(t.size),
        median_ratio=float(np.median(t) / CHI2_2_MEDIAN),
        median_ratio_angle=float(np.median(ta) / CHI2_1_MEDIAN),
        fraction_beyond_95=float(np.mean(t > CHI2_2_95)),
    )


def pass_consistency_of_results(directory: str | Path, gap_s: float = 30.0) -> PassConsistency:
    """:func:`pass_consistency` of a results folder's ``graph.g2o``.

    Raises
    ------
    EvaluationError
        The file states no scan time stamps (``LINESLAM_SCAN`` lines).
    """
    f = read_line_graph_g2o(Path(directory) / "graph.g2o")
    if f.timestamps is None:
        raise EvaluationError(f"{directory}/graph.g2o states no scan time stamps")
    return pass_consistency(line_graph_from_file(f), f.timestamps, f.robust_kernel, gap_s)
