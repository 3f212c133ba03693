"""Evaluation of trajectories: relations metric (Cartographer's), ATE, RPE, NEES, relations NEES.

Main entry points::

    from slam.evaluation import relations_metric, ate, rpe, pose_nees, evaluate_results
    from slam.evaluation import relations_nees      # with relative-pose covariances
    from slam.evaluation import error_onsets        # where a run's error entered

    metric = relations_metric(trajectory, read_relations(path))   # Kümmerle et al.
    print(metric.cartographer_report())

Every result has ``to_dict()`` for ``metrics.json``.
"""

from slam.evaluation.ate import AteResult, align_se2, ate
from slam.evaluation.nees import (
    CorrelatedBounds,
    NeesResult,
    correlated_nees_bounds,
    nees_bounds,
    nees_values,
    pose_nees,
    pose_nees_values,
)
from slam.evaluation.onsets import ErrorOnset, error_onsets
from slam.evaluation.relations_metric import (
    MeanStd,
    RelationsMetric,
    relation_errors,
    relations_metric,
    relations_within,
)
from slam.evaluation.relations_nees import RelationsNees, relation_error_vectors, relations_nees
from slam.evaluation.report import EvaluationReport, evaluate_results
from slam.evaluation.rpe import RpeResult, distance_pairs, rpe, rpe_errors
from slam.evaluation.stats import ErrorStats
from slam.evaluation.timestamps import associate, match_timestamps

__all__ = [
    "AteResult",
    "CorrelatedBounds",
    "ErrorOnset",
    "ErrorStats",
    "EvaluationReport",
    "MeanStd",
    "NeesResult",
    "RelationsMetric",
    "RelationsNees",
    "RpeResult",
    "align_se2",
    "associate",
    "ate",
    "correlated_nees_bounds",
    "distance_pairs",
    "error_onsets",
    "evaluate_results",
    "match_timestamps",
    "nees_bounds",
    "nees_values",
    "pose_nees",
    "pose_nees_values",
    "relation_error_vectors",
    "relation_errors",
    "relations_metric",
    "relations_nees",
    "relations_within",
    "rpe",
    "rpe_errors",
]
