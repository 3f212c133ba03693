"""Comparison runs: several estimator variants on the same data, evaluated, one report.

The pieces, in the order a comparison uses them:

* :mod:`slam.experiments.variants` — what runs: the variants (:func:`default_variants`) and
  the data source (:func:`parse_source`: ``sim:WORLD[:LOOPS[:SEED]]`` or a log);
* :mod:`slam.experiments.tasks` — one variant on the source, loaded, run and evaluated in a
  worker (:func:`~slam.experiments.tasks.run_variant`);
* :func:`run_compare` (here) — one task per variant through
  :func:`slam.experiments.parallel.map_tasks` (serially, on local processes, or on a Dask
  cluster), the outcomes collected in order;
* :mod:`slam.experiments.report` — the table, notes and figures
  (:func:`~slam.experiments.report.write_report`).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from slam.config import RunConfig
from slam.errors import ConfigError
from slam.experiments.linesim import LineSimConfig
from slam.experiments.parallel import map_tasks
from slam.experiments.report import CompareReport
from slam.experiments.tasks import CompareTask, prepare_log_cache, run_variant
from slam.experiments.variants import DataSpec, Variant

__all__ = ["run_compare"]


def run_compare(
    data: DataSpec,
    variants: tuple[Variant, ...],
    run_config: RunConfig | None = None,
    workers: int = 1,
    dask_address: str | None = None,
    progress: Any = None,
    sim: LineSimConfig | None = None,
    cache_dir: str | Path | None = None,
    max_scans: int | None = None,
) -> CompareReport:
    """Run every variant on the data (one task each) and collect the outcomes in order.

    For a log, the lines are extracted once per line-fit configuration (weighted /
    unweighted) before the variants run, and cached as pickles in ``cache_dir`` where every
    worker reads them (a Dask cluster needs ``cache_dir`` on a shared file system).

    Parameters
    ----------
    data : DataSpec
        The source (:func:`slam.experiments.variants.parse_source`).
    variants : tuple of Variant
        What to run; names must be unique.
    run_config : RunConfig, optional
        Estimator settings shared by every variant (defaults if None).
    workers : int
        Local worker processes (``<= 1``: serial).
    dask_address : str, optional
        A Dask scheduler to run on instead.
    progress : callable, optional
        ``progress(done, total)``.
    sim : LineSimConfig, optional
        Noise of the line-level simulator (simulated sources).
    cache_dir : str or Path, optional
        Folder of the line-fit cache of a log.
    max_scans : int, optional
        Use only the first scans of a log.
    """
    names = [v.name for v in variants]
    if len(set(names)) != len(names):
        raise ConfigError(f"variant names must be unique, got {names}")
    if not variants:
        raise ConfigError("no variants to compare")
    rc = run_config or RunConfig()
    cache = None if cache_dir is None else str(cache_dir)
    tasks = [CompareTask(data, v, rc, sim or LineSimConfig(), cache, max_scans) for v in variants]
    t0 = time.perf_counter()
    if data.kind == "log" and cache_dir is not None:
        prepare_log_cache(tasks, cache_dir)
    outcomes = map_tasks(run_variant, tasks, workers, dask_address, progress)
    return CompareReport(data, outcomes, time.perf_counter() - t0)
