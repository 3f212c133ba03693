"""What a comparison runs: the variant catalogue, and where the data come from.

A :class:`Variant` names an estimator (:data:`slam.experiments.estimators.ESTIMATORS`) and the
front-end choices that matter for the paper's claims (weighted or unweighted line fits; the
association is part of the estimator name, e.g. ``ekf-nn`` / ``ekf-jcbb``).
:func:`default_variants` is the catalogue ``lineslam compare`` runs; :func:`parse_variants`
reads a user's choice.

A :class:`DataSpec` says where the scans come from (:func:`parse_source`):

* ``sim:WORLD[:LOOPS[:SEED]]`` — the line-level simulator (:mod:`slam.experiments.linesim`),
  with ground truth;
* a log (a CARMEN file, a ROS bag or a registered dataset name), with the relations and
  ground truth given (``--relations``, ``--ground-truth``), else the catalogue's relations or
  those found next to it.

Both are small picklable values: every comparison task carries them to its worker, which
loads the data itself (:mod:`slam.experiments.tasks`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from slam.errors import ConfigError
from slam.experiments.estimators import ESTIMATORS
from slam.experiments.linesim import world_and_trajectory

__all__ = [
    "GRAPH_BATCH_BUDGET_S",
    "DataSpec",
    "Variant",
    "default_variants",
    "parse_source",
    "parse_variants",
]


@dataclass(frozen=True)
class Variant:
    """One configuration to compare.

    Attributes
    ----------
    name : str
        Label in the report (unique).
    estimator : str
        Key of :data:`slam.experiments.estimators.ESTIMATORS`.
    weighted : bool
        Weighted (the paper's) or unweighted line fits; only meaningful for real logs.
    time_budget_s : float or None
        Stop feeding scans once the estimator has run this long (the report says at which
        scan); None: no limit.
    """

    name: str
    estimator: str
    weighted: bool = True
    time_budget_s: float | None = None

    def __post_init__(self) -> None:
        if self.estimator not in ESTIMATORS:
            raise ConfigError(
                f"variant {self.name!r}: unknown estimator {self.estimator!r}; "
                f"known: {', '.join(sorted(ESTIMATORS))}"
            )


GRAPH_BATCH_BUDGET_S = 150.0
"""Time budget (s) of the ``graph-batch`` variant on logs (see :func:`default_variants`)."""


def default_variants(simulated: bool) -> tuple[Variant, ...]:
    """The variants ``lineslam compare`` runs by default (those whose estimators exist).

    Every variant runs with the default configuration of its estimator (one for all logs):
    the graph with the batch and the iSAM2 back-end, the EKF with JCBB (its default) and with
    nearest neighbour, odometry only, and for logs the unweighted line fits (graph iSAM2 and
    EKF).  The graph's association is its registration front end's (nearest neighbour after
    registration, :mod:`slam.frontend.registration`), which has no JCBB option, so the NN vs
    JCBB comparison is made on the EKF.

    On logs the online batch back-end (a warm-started solve of the whole graph every keyframe,
    ``O(graph)`` per keyframe) gets :data:`GRAPH_BATCH_BUDGET_S` seconds: on Intel it reached
    5632 of 13631 scans in 8 minutes and was slowing down, so running it to the end would
    take the comparison far past its 15-minute budget.  The report says where it stopped.
    """
    # longest first: tasks start in this order, so a pool of workers finishes sooner
    names = [
        ("graph-batch", "graph-batch", True),
        ("graph-isam2", "graph-isam2", True),
        ("graph-isam2-unweighted", "graph-isam2", False),
        ("ekf", "ekf-jcbb", True),
        ("ekf-nn", "ekf-nn", True),
        ("ekf-unweighted", "ekf-jcbb", False),
        ("odometry", "odometry", True),
    ]
    if simulated:  # the simulator's lines are not fitted: no weighted / unweighted choice
        names = [n for n in names if n[2]]
    return tuple(
        Variant(n, e, w, None if simulated or e != "graph-batch" else GRAPH_BATCH_BUDGET_S)
        for n, e, w in names
        if e in ESTIMATORS
    )


def parse_variants(spec: str) -> tuple[Variant, ...]:
    """Variants from a comma-separated list of ``NAME=ESTIMATOR[/unweighted]`` or ``ESTIMATOR``.

    ``ekf=ekf-nn,flat=graph-isam2/unweighted,odometry`` gives the variant ``ekf`` (estimator
    ``ekf-nn``), ``flat`` (``graph-isam2`` on unweighted fits) and ``odometry``.  Empty items
    are skipped; an unknown estimator raises :class:`~slam.errors.ConfigError`.
    """
    chosen = []
    for item in (v.strip() for v in spec.split(",") if v.strip()):
        name, _, estimator_spec = item.partition("=")
        estimator_spec = estimator_spec or name
        estimator, _, flag = estimator_spec.partition("/")
        chosen.append(Variant(name, estimator, weighted=flag != "unweighted"))
    return tuple(chosen)


@dataclass(frozen=True)
class DataSpec:
    """Where the data of a comparison come from (picklable, resolved inside each task).

    Attributes
    ----------
    kind : {"sim", "log"}
    name : str
        World name (sim) or log path / registered dataset name (log).
    loops : float
        Route repetitions (sim).
    seed : int
        Simulation seed (sim).
    relations, ground_truth : str or None
        Files to evaluate a log against (``--relations``, ``--ground-truth``); default the
        catalogue's relations, or those beside the log (:class:`slam.experiments.logdata.LogData`).
    """

    kind: str
    name: str
    loops: float = 1.0
    seed: int = 0
    relations: str | None = None
    ground_truth: str | None = None

    @property
    def label(self) -> str:
        """Short name for reports."""
        if self.kind == "sim":
            return f"sim:{self.name}:{self.loops:g}:{self.seed}"
        if "/" not in self.name:
            return self.name
        path = Path(self.name)  # a file named like its folder's log, e.g. sim/demo/log.clf
        return path.parent.name if path.stem == "log" else path.stem


def parse_source(
    source: str,
    seed: int = 0,
    relations: str | Path | None = None,
    ground_truth: str | Path | None = None,
) -> DataSpec:
    """``sim:WORLD[:LOOPS[:SEED]]`` or a log path / dataset name.

    ``seed`` is the simulation seed when the source names none.  ``relations`` and
    ``ground_truth`` (files) are for logs; a simulated source has its own ground truth.
    """
    if source.startswith("sim:"):
        parts = source.split(":")
        try:
            loops = float(parts[2]) if len(parts) > 2 and parts[2] else 1.0
            run_seed = int(parts[3]) if len(parts) > 3 and parts[3] else seed
        except ValueError as exc:
            raise ConfigError(f"bad simulated source {source!r}: sim:WORLD[:LOOPS[:SEED]]") from exc
        world_and_trajectory(parts[1], 1.0)  # validates the world name
        if relations is not None or ground_truth is not None:
            raise ConfigError("a simulated source has its own ground truth: no --relations")
        return DataSpec("sim", parts[1], loops, run_seed)
    for what, value in (("--relations", relations), ("--ground-truth", ground_truth)):
        if value is not None and not Path(value).is_file():
            raise ConfigError(f"{what} {value}: no such file")
    return DataSpec(
        "log",
        source,
        relations=None if relations is None else str(relations),
        ground_truth=None if ground_truth is None else str(ground_truth),
    )
