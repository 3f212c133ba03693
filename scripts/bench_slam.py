"""Benchmark of the whole ``lineslam slam`` pipeline on a real log, time per stage.

Runs the pipeline (read, extract, front end, associate, fuse, loop closing, optimise, write)
exactly as ``lineslam slam LOG --out DIR`` does, once per back-end, side by side in one run,
and prints for each a table of wall-clock seconds whose rows **partition** the run's total:

* every stage of the pipeline's clock (:class:`slam.line_slam.clock.StageClock`) is counted
  *exclusive* of the stages nested in it: ``judge (in loop_closure)`` and ``backend (in
  loop_closure)`` run inside loop closing and are their own rows, ``loop_closure`` is what
  remains; ``fusion (in optimize)`` is the final fusion inside ``optimize``;
* ``extract`` is all the line extraction the pipeline does (it extracts keyframe scans only;
  their number is printed);
* ``read`` and ``write`` are the runner's; ``estimate (other)`` is the rest of feeding the
  scans (odometry steps of the scans that are not keyframes, bookkeeping), ``optimize`` the
  final convergence without its nested stages, ``result (other)`` assembling the result
  without ``covariances``; ``unaccounted`` is the total minus all rows (the runner's own
  glue), so the rows add to ``total`` exactly.

Also printed: the process CPU time of each run (both cores may be used by BLAS/GTSAM), scans
per second and the ratio of the back-ends' totals.  With ``--relations`` the relations error
of each run is printed too, so a speed-up that costs accuracy shows.

    LINESLAM_DATA=/path/to/shared/datasets .venv/bin/python scripts/bench_slam.py intel
    .venv/bin/python scripts/bench_slam.py intel --max-scans 2000 --backend batch
    .venv/bin/python scripts/bench_slam.py intel --backend isam2 --config coarse.toml --relations

With ``--config`` every back-end also runs with that configuration, one run after the other in
the same process, and the totals are printed as ratios to the first run.

Target: the whole Intel log (13,631 scans) in under 120 s on a 2-core machine (Cartographer
reports 179 s for it).
"""

from __future__ import annotations

import argparse
import functools
import platform
import tempfile
import time
from collections import defaultdict
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from typing import Any, Literal, cast

from slam.config import RunConfig
from slam.line_slam import clock as stage_clock
from slam.line_slam.pipeline import LineSlam
from slam.runner import run_slam

#: Rows in pipeline order; any other exclusive stage found is printed after them.
ROWS = (
    "read",
    "extract",
    "frontend",
    "associate",
    "backend",
    "fusion",
    "loop_closure",
    "judge (in loop_closure)",
    "backend (in loop_closure)",
    "estimate (other)",
    "optimize",
    "fusion (in optimize)",
    "backend (in optimize)",
    "covariances",
    "result (other)",
    "write",
    "unaccounted",
)

#: Exclusive wall-clock seconds per row of the run in progress.
_EXCLUSIVE: defaultdict[str, float] = defaultdict(float)
#: Open frames: [row, start time, seconds spent in nested frames].
_STACK: list[list[Any]] = []
_OUTER = ("estimate (other)", "result (other)")


@contextmanager
def _frame(stage: str) -> Iterator[None]:
    """Time a block exclusive of the frames nested in it (one row of the partition)."""
    parent = _STACK[-1][0] if _STACK else None
    row = stage if parent is None or parent in _OUTER else f"{stage} (in {parent})"
    _STACK.append([row, time.perf_counter(), 0.0])
    try:
        yield
    finally:
        row, t0, nested = _STACK.pop()
        dt = time.perf_counter() - t0
        _EXCLUSIVE[row] += dt - nested
        if _STACK:
            _STACK[-1][2] += dt


def _install_frames() -> None:
    """Route the pipeline's stage clock and its outer calls through :func:`_frame`."""
    original = stage_clock.StageClock.__call__

    @contextmanager
    def timed(self: stage_clock.StageClock, stage: str) -> Iterator[None]:
        with _frame(stage), original(self, stage):
            yield

    stage_clock.StageClock.__call__ = timed  # type: ignore[method-assign]

    def wrap(name: str, row: str) -> None:
        method: Callable[..., Any] = getattr(LineSlam, name)

        @functools.wraps(method)
        def framed(self: LineSlam, *args: Any, **kwargs: Any) -> Any:
            with _frame(row):
                return method(self, *args, **kwargs)

        setattr(LineSlam, name, framed)

    wrap("add_scans", "estimate (other)")
    wrap("add_scan", "estimate (other)")
    wrap("optimize", "optimize")
    wrap("result", "result (other)")


def run_once(
    log: str, backend: str, max_scans: int | None, out: Path, config_path: Path | None = None
) -> tuple[dict[str, Any], dict[str, float], float]:
    """Run the pipeline with one back-end (from a TOML configuration if given).

    Returns its summary, the partition of its total (exclusive seconds per row, ``total``
    included) and its process CPU time (s).
    """
    config = RunConfig() if config_path is None else RunConfig.from_toml(config_path)
    kind = cast(Literal["batch", "isam2"], backend)
    config = replace(config, slam=replace(config.slam, backend=kind))
    _EXCLUSIVE.clear()
    c0 = time.process_time()
    summary = run_slam(log, out, config, max_scans=max_scans)
    cpu = time.process_time() - c0
    runtime = summary["runtime_s"]
    rows = dict(_EXCLUSIVE)
    rows["read"] = float(runtime.get("read", 0.0))
    rows["write"] = float(runtime.get("write", 0.0))
    rows["total"] = float(runtime["total"])
    rows["unaccounted"] = rows["total"] - sum(v for k, v in rows.items() if k != "total")
    return summary, rows, cpu


def relations_error(out: Path, log: str) -> tuple[float, float, int] | None:
    """Mean absolute translational (m) and rotational (deg) relations error of the run, and
    the number of relations used (those inside the run, for ``--max-scans``); None without
    a relations file."""
    from slam.evaluation import relations_metric, relations_within
    from slam.io.catalog import resolve_log
    from slam.io.relations import read_relations
    from slam.io.tum import read_tum

    resolved = resolve_log(log)
    if resolved.relations is None:
        return None
    trajectory = read_tum(out / "trajectory.tum")
    relations = relations_within(read_relations(resolved.relations), trajectory.timestamps)
    metric = relations_metric(trajectory, relations)
    return metric.abs_trans_m.mean, metric.abs_rot_deg.mean, metric.n_used


def _cpu_model() -> str:
    """The CPU model and the number of logical CPUs (Linux ``/proc/cpuinfo``)."""
    try:
        lines = Path("/proc/cpuinfo").read_text().splitlines()
    except OSError:
        return "cpu unknown"
    models = [ln.split(":", 1)[1].strip() for ln in lines if ln.startswith("model name")]
    return f"{models[0] if models else 'cpu unknown'} x {len(models)}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("log", nargs="?", default="intel", help="log file or dataset name")
    parser.add_argument("--max-scans", type=int, default=None)
    parser.add_argument(
        "--backend",
        action="append",
        choices=("batch", "isam2"),
        help="back-end(s) to time; default both, side by side",
    )
    parser.add_argument(
        "--relations", action="store_true", help="also print the relations error of each run"
    )
    parser.add_argument(
        "--config",
        type=Path,
        action="append",
        default=[],
        help="also run each back-end with this TOML configuration (side by side with the "
        "defaults; repeatable)",
    )
    args = parser.parse_args()
    # runs: every back-end with the defaults, then with each --config
    runs: list[tuple[str, str, Path | None]] = []
    for backend in args.backend or ["batch", "isam2"]:
        runs.append((backend, backend, None))
        runs += [(f"{backend}:{c.stem}", backend, c) for c in args.config]
    backends = [label for label, _, _ in runs]

    _install_frames()
    summaries: dict[str, dict[str, Any]] = {}
    partitions: dict[str, dict[str, float]] = {}
    cpu: dict[str, float] = {}
    errors: dict[str, tuple[float, float, int] | None] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for k, (label, backend, config_path) in enumerate(runs):
            out = Path(tmp) / f"run{k}"
            summaries[label], partitions[label], cpu[label] = run_once(
                args.log, backend, args.max_scans, out, config_path
            )
            errors[label] = relations_error(out, args.log) if args.relations else None

    n_scans = {b: int(s.get("scans", 0)) for b, s in summaries.items()}
    print(f"log {args.log}: {next(iter(n_scans.values()))} scans")
    print(f"machine: {platform.processor() or platform.machine()}, {_cpu_model()}")
    for b in backends:
        print(f"{b}: {summaries[b].get('keyframes', '?')} keyframes (the scans extracted)")
    keys = [k for k in ROWS if any(k in p for p in partitions.values())]
    keys += sorted({k for p in partitions.values() for k in p} - set(keys) - {"total"})
    width = max(12, *(len(b) + 2 for b in backends))
    label_w = max(len(k) for k in keys) + 2
    print("wall-clock seconds, exclusive of nested stages (the rows add to the total)")
    print(f"{'stage (s)':<{label_w}}" + "".join(f"{b:>{width}}" for b in backends))
    for key in [*keys, "total"]:
        times = [partitions[b].get(key, 0.0) for b in backends]
        row = "".join(f"{t:>{width}.2f}" for t in times)
        print(f"{key:<{label_w}}{row}")
    print(f"{'process CPU s':<{label_w}}" + "".join(f"{cpu[b]:>{width}.2f}" for b in backends))
    rate = "".join(f"{n_scans[b] / partitions[b]['total']:>{width}.1f}" for b in backends)
    print(f"{'scans/s':<{label_w}}{rate}")
    if args.relations:
        for b in backends:
            e = errors[b]
            if e is not None:
                print(f"relations {b}: {e[0]:.4f} m, {e[1]:.3f} deg (mean abs, {e[2]} used)")
    a = backends[0]
    for b in backends[1:]:
        ratio = partitions[b]["total"] / partitions[a]["total"]
        print(f"total {b} / {a}: {ratio:.2f}")


if __name__ == "__main__":
    main()
