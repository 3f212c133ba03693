"""Factor-graph line SLAM on GTSAM: line landmarks, vectorised linearisation, GN/LM, iSAM2.

Main entry point::

    from slam.graph import LineSlam, SlamConfig

    slam = LineSlam(SlamConfig(backend="isam2"))
    for scan in scans:              # slam.types.Scan, with odometry
        slam.add_scan(scan)         # or add_scan(scan, lines) with lines already extracted
    slam.optimize()
    result = slam.result()          # SlamResult: poses, covariances, line map; .write(out_dir)

Lower layers for research use: :class:`LineGraph` (the problem as numpy arrays),
:class:`BatchSolver` (own Gauss-Newton / Levenberg-Marquardt loop with GTSAM elimination),
:class:`Isam2Solver` (incremental), :func:`linearize_line_factors` (the vectorised fast path)
and :func:`line_custom_factor` (the ``gtsam.CustomFactor`` reference).  See ``docs/graph.md``.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from slam.graph.batch import BatchSolver, SolveStats
    from slam.graph.config import (
        FusionConfig,
        Isam2Config,
        KeyframeConfig,
        LoopClosureConfig,
        MotionNoiseConfig,
        SlamConfig,
        SolverConfig,
    )
    from slam.graph.custom_factor import line_custom_factor, values_from_arrays
    from slam.graph.factors import linearize_line_factors, sqrt_information_2x2
    from slam.graph.isam2 import Isam2Solver
    from slam.graph.line_slam import LineSlam, ScanReport, SlamWarning
    from slam.graph.problem import LineGraph
    from slam.graph.result import SlamResult
    from slam.graph.synthetic import SyntheticProblem, synthetic_problem

__all__ = [
    "BatchSolver",
    "FusionConfig",
    "Isam2Config",
    "Isam2Solver",
    "KeyframeConfig",
    "LineGraph",
    "LineSlam",
    "LoopClosureConfig",
    "MotionNoiseConfig",
    "ScanReport",
    "SlamConfig",
    "SlamResult",
    "SlamWarning",
    "SolveStats",
    "SolverConfig",
    "SyntheticProblem",
    "line_custom_factor",
    "linearize_line_factors",
    "sqrt_information_2x2",
    "synthetic_problem",
    "values_from_arrays",
]


_LAZY = {
    "BatchSolver": "slam.graph.batch",
    "FusionConfig": "slam.graph.config",
    "Isam2Config": "slam.graph.config",
    "Isam2Solver": "slam.graph.isam2",
    "KeyframeConfig": "slam.graph.config",
    "LoopClosureConfig": "slam.graph.config",
    "LineGraph": "slam.graph.problem",
    "LineSlam": "slam.graph.line_slam",
    "MotionNoiseConfig": "slam.graph.config",
    "ScanReport": "slam.graph.line_slam",
    "SlamConfig": "slam.graph.config",
    "SlamResult": "slam.graph.result",
    "SlamWarning": "slam.graph.line_slam",
    "SolveStats": "slam.graph.batch",
    "SolverConfig": "slam.graph.config",
    "SyntheticProblem": "slam.graph.synthetic",
    "line_custom_factor": "slam.graph.custom_factor",
    "linearize_line_factors": "slam.graph.factors",
    "sqrt_information_2x2": "slam.graph.factors",
    "synthetic_problem": "slam.graph.synthetic",
    "values_from_arrays": "slam.graph.custom_factor",
}


def __getattr__(name: str) -> Any:
    """Import on first use: ``slam.graph.config`` must not pull in gtsam."""
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'slam.graph' has no attribute {name!r}")
