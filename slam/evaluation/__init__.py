"""Evaluation of trajectories: the relations metric (Cartographer's), ATE, RPE, NEES."""

from slam.evaluation.relations_metric import (
    MeanStd,
    RelationsMetric,
    match_timestamps,
    relation_errors,
    relations_metric,
)

__all__ = [
    "MeanStd",
    "RelationsMetric",
    "match_timestamps",
    "relation_errors",
    "relations_metric",
]
