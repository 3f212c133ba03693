"""The GTSAM back-end: line factors, vectorised linearisation, Gauss-Newton/LM, iSAM2.

:class:`LineGraph` holds the problem as numpy arrays (poses, anchored line landmarks, line and
odometry factors); :class:`BatchSolver` runs its own Gauss-Newton / Levenberg-Marquardt loop with
GTSAM's elimination (or a compiled sparse LDLᵀ); :class:`Isam2Solver` updates incrementally;
:func:`linearize_line_factors` is the vectorised fast path and :func:`line_custom_factor` the
``gtsam.CustomFactor`` reference it is tested against.  See ``docs/graph.md``.

The SLAM pipeline that feeds this back-end is :class:`slam.line_slam.LineSlam` (a higher
layer: nothing here imports it).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from slam.graph.batch import BatchSolver, SolveStats
    from slam.graph.config import Isam2Config, SolverConfig
    from slam.graph.custom_factor import line_custom_factor, values_from_arrays
    from slam.graph.factors import linearize_line_factors, sqrt_information_2x2
    from slam.graph.isam2 import Isam2Solver
    from slam.graph.problem import LineGraph
    from slam.graph.synthetic import SyntheticProblem, synthetic_problem

__all__ = [
    "BatchSolver",
    "Isam2Config",
    "Isam2Solver",
    "LineGraph",
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
    "Isam2Config": "slam.graph.config",
    "Isam2Solver": "slam.graph.isam2",
    "LineGraph": "slam.graph.problem",
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
    """Import on first use (``slam.graph.config`` must not pull in gtsam)."""
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'slam.graph' has no attribute {name!r}")
