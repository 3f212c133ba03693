"""Exports of a results folder (``lineslam export DIR --format FORMAT --out PATH``).

Main entry point::

    export_results(results_dir, "occupancy", "out/map", resolution_m=0.05) -> list[Path]

Formats
-------
``occupancy``
    A map_server occupancy grid ``PATH.pgm`` + ``PATH.yaml`` (:mod:`slam.io.occupancy`),
    ray-traced from the log's scans at the estimated poses.  The log is the one the run read
    (``summary.json``'s ``"log"``, opened with the folder's ``config.toml``), or ``log=``.
    Scans are used where the estimated laser pose moved ``min_distance_m`` or turned
    ``min_angle_rad`` since the last one used (all scans with 0 and 0).
``geojson``
    The line map as a GeoJSON FeatureCollection (:mod:`slam.io.geojson`).
``svg``
    The line map and the trajectory as an SVG picture (:mod:`slam.io.svg`).
``g2o``
    The factor graph of ``lineslam slam`` (``graph.g2o``, :func:`slam.io.g2o.write_line_graph_g2o`):
    poses and odometry for ``gtsam.readG2o`` and g2o, the line landmarks and their factors as
    a documented extension.  EKF results have no graph.
``tum``
    The trajectory (``trajectory.tum``), in the frame ``summary.json`` names.

The files are written under temporary names beside ``PATH`` and renamed into place when
complete (:func:`slam.io.atomic.staged_files`): a failed or interrupted export leaves an
earlier file at ``PATH`` as it was.  ``PATH`` must not be one of the results folder's files
or the log (:class:`~slam.errors.OutputError`).
"""

from __future__ import annotations

import contextlib
import json
import shutil
from pathlib import Path
from typing import Any

import numpy as np

from slam import interrupts
from slam.errors import InputError
from slam.geometry import pose_compose

__all__ = ["EXPORT_FORMATS", "export_results"]

EXPORT_FORMATS = ("occupancy", "geojson", "svg", "g2o", "tum")


def _map_doc(results_dir: Path) -> dict[str, Any]:
    path = results_dir / "map.json"
    if not path.is_file():
        raise InputError("no map.json in the results folder", str(results_dir))
    doc: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
    return doc


def laser_poses_of_results(results: Any, mount_fallback: Any = None) -> np.ndarray:
    """The laser poses ``(n, 3)`` of a results folder: its poses, moved by the mounting if base."""
    poses = np.asarray(results.trajectory.poses, dtype=float)
    if results.frame != "base":
        return poses
    mount = results.summary.get("input", {}).get("pose_base_laser", mount_fallback)
    if mount is None:
        raise InputError(
            "the trajectory is for the base and summary.json does not say the laser mounting",
            str(results.directory),
        )
    return pose_compose(poses, np.broadcast_to(np.asarray(mount, float), poses.shape))


def export_occupancy(
    results_dir: Path,
    out: Path,
    *,
    into: tuple[Path, Path] | None = None,
    resolution_m: float = 0.05,
    log: str | Path | None = None,
    min_distance_m: float = 0.1,
    min_angle_rad: float = 0.1,
) -> list[Path]:
    """The ``occupancy`` format (module docstring); ``into``: the files to write (temporary)."""
    from slam.config import open_run_log
    from slam.io.occupancy import occupancy_grid, select_scans, write_map_server
    from slam.io.results import read_results

    results = read_results(results_dir)
    log = _log_of(results_dir, results.summary, log)
    source = open_run_log(log, _config_of(results_dir))
    poses = laser_poses_of_results(results, source.policy.pose_base_laser)
    stamps = results.trajectory.timestamps
    keep = select_scans(poses, min_distance_m, min_angle_rad)
    wanted = set(keep)
    scans = []
    n = 0
    for k, scan in enumerate(source.scans(len(stamps))):
        interrupts.check()  # between scans (slam.interrupts)
        n = k + 1
        if abs(scan.timestamp - stamps[k]) > 1e-5:
            raise InputError(
                f"scan {k} of {source.log} has time stamp {scan.timestamp:.6f}, the trajectory "
                f"{stamps[k]:.6f}: not the log of this run (give --log)",
                str(results_dir),
            )
        if k in wanted:
            scans.append(scan)
    if n < len(stamps):
        raise InputError(f"{source.log} has {n} scans, the trajectory {len(stamps)}")
    grid = occupancy_grid(poses[keep], scans, resolution_m)
    interrupts.check()
    return list(write_map_server(grid, out, into=into))


def _log_of(results_dir: Path, summary: dict[str, Any], log: str | Path | None) -> str | Path:
    log = log if log is not None else summary.get("log")
    if log is None:
        raise InputError("summary.json names no log: give --log", str(results_dir))
    return log


def _config_of(results_dir: Path) -> Any:
    from slam.config import RunConfig

    config_path = results_dir / "config.toml"
    return RunConfig.from_toml(config_path) if config_path.is_file() else RunConfig()


def _targets(fmt: str, out: Path) -> list[Path]:
    """The files ``fmt`` writes for ``--out out``."""
    if fmt == "occupancy":
        from slam.io.occupancy import map_server_paths

        return list(map_server_paths(out))
    return [out]


def _inputs(results_dir: Path, fmt: str, log: str | Path | None) -> list[Path]:
    """What an export reads: the results folder's files and, for ``occupancy``, the log."""
    from slam.io.results import TRAJECTORY_FILE

    names = (TRAJECTORY_FILE, "trajectory_covariance.txt", "map.json", "graph.g2o")
    out = [results_dir / name for name in (*names, "summary.json", "config.toml")]
    if fmt == "occupancy":
        summary_path = results_dir / "summary.json"
        named = log
        if named is None and summary_path.is_file():
            with contextlib.suppress(ValueError, OSError):
                named = json.loads(summary_path.read_text(encoding="utf-8")).get("log")
        if named is not None and Path(named).exists():
            out.append(Path(named))
    return out


def export_results(
    results_dir: str | Path,
    fmt: str,
    out: str | Path,
    *,
    resolution_m: float = 0.05,
    log: str | Path | None = None,
    min_distance_m: float = 0.1,
    min_angle_rad: float = 0.1,
) -> list[Path]:
    """Write ``fmt`` (one of :data:`EXPORT_FORMATS`) of a results folder to ``out``.

    Returns the files written.

    Raises
    ------
    InputError
        An unknown format, or the folder lacks what the format needs.
    OutputError
        ``out`` cannot be written, or is one of the files the export reads.
    """
    from slam.io.atomic import staged_files

    results_dir = Path(results_dir)
    out = Path(out)
    if not results_dir.is_dir():
        raise InputError("not a results folder (no such directory)", str(results_dir))
    if fmt not in EXPORT_FORMATS:
        raise InputError(f"unknown export format {fmt!r} (one of {', '.join(EXPORT_FORMATS)})")
    targets = _targets(fmt, out)
    with staged_files(targets, inputs=_inputs(results_dir, fmt, log)) as work:
        _export(results_dir, fmt, out, work, resolution_m, log, min_distance_m, min_angle_rad)
    return targets


def _export(
    results_dir: Path,
    fmt: str,
    out: Path,
    work: list[Path],
    resolution_m: float,
    log: str | Path | None,
    min_distance_m: float,
    min_angle_rad: float,
) -> None:
    """Write ``fmt`` into the temporary files ``work`` (one per target of :func:`_targets`)."""
    if fmt == "occupancy":
        export_occupancy(
            results_dir,
            out,
            into=(work[0], work[1]),
            resolution_m=resolution_m,
            log=log,
            min_distance_m=min_distance_m,
            min_angle_rad=min_angle_rad,
        )
    elif fmt == "geojson":
        from slam.io.geojson import write_geojson

        write_geojson(work[0], _map_doc(results_dir))
    elif fmt == "svg":
        from slam.io.results import TRAJECTORY_FILE
        from slam.io.svg import write_svg
        from slam.io.tum import read_tum

        tum = results_dir / TRAJECTORY_FILE
        traj = read_tum(tum).poses if tum.is_file() else None
        write_svg(work[0], _map_doc(results_dir), traj)
    elif fmt == "g2o":
        graph = results_dir / "graph.g2o"
        if not graph.is_file():
            raise InputError(
                "no graph.g2o in the results folder (lineslam slam writes it; the EKF has no "
                "graph)",
                str(results_dir),
            )
        shutil.copyfile(graph, work[0])
    else:  # tum
        from slam.io.results import TRAJECTORY_FILE

        tum = results_dir / TRAJECTORY_FILE
        if not tum.is_file():
            raise InputError(f"no {TRAJECTORY_FILE} in the results folder", str(results_dir))
        shutil.copyfile(tum, work[0])
