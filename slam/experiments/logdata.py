"""A log's scans with their extracted lines, and what to evaluate against.

:func:`load_log` resolves a ``LOG`` argument (path or registered dataset name) with
:mod:`slam.io`, reads the scans, extracts each scan's lines with :func:`linefit.extract_lines`
and finds the log's relations (and ground truth, for simulated logs that carry one).  The
result can be cached on disk (:func:`cached_log_data`), so the variants of a comparison extract
lines once per line-fit configuration.
"""

from __future__ import annotations

import hashlib
import pickle
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from linefit.config import LineFitConfig
from linefit.line import Line
from linefit.tomlconfig import config_to_dict, to_toml_string
from slam.errors import DatasetError
from slam.inputs import InputPolicy, ScannerConfig
from slam.types import Scan

__all__ = ["LogData", "cached_log_data", "load_log"]


@dataclass(frozen=True, eq=False)
class LogData:
    """Scans of one log with their lines.

    Attributes
    ----------
    name : str
        Dataset name or file stem.
    log_path : Path
    scans : list of Scan
    lines : list of list of Line
        Lines of each scan in the laser frame, as fitted (estimators apply their own filters).
    relations_path : Path or None
        Relations file of the log: the one given, else the catalogue's, else
        ``relations.txt`` beside the log (a ``lineslam simulate`` folder).
    ground_truth_path : Path or None
        The one given, else ``ground_truth.tum`` beside the log, if present.
    extraction_s : float
        Time spent extracting lines.
    policy : InputPolicy
        How the log's odometry is read and which frame is reported
        (:func:`slam.inputs.open_log`).
    """

    name: str
    log_path: Path
    scans: list[Scan]
    lines: list[list[Line]]
    relations_path: Path | None
    ground_truth_path: Path | None
    extraction_s: float
    policy: InputPolicy = field(default_factory=InputPolicy)

    @property
    def n_points(self) -> int:
        """Valid range readings over all scans."""
        return int(sum(int(s.valid_mask().sum()) for s in self.scans))


def load_log(
    source: str | Path,
    linefit_config: LineFitConfig,
    max_scans: int | None = None,
    progress: Callable[[int], None] | None = None,
    odometry_sign: str | None = None,
    scanner: ScannerConfig | None = None,
    relations: str | Path | None = None,
    ground_truth: str | Path | None = None,
) -> LogData:
    """Read a log and extract every scan's lines.

    Parameters
    ----------
    source : str or Path
        A CARMEN log, a ROS bag, or a registered dataset name (``intel``, ``aces``, ``fr079``).
    linefit_config : LineFitConfig
    max_scans : int, optional
        Read only the first scans.
    progress : callable, optional
        Called with the number of scans read so far (every 100 scans).
    odometry_sign : {"velocity", "logged"}, optional
        Overrides ``scanner.odometry_sign`` (:func:`slam.io.carmen.iter_log_scans`).
    scanner : ScannerConfig, optional
        The ``[scanner]`` settings the log is opened with (:func:`slam.inputs.open_log`).
    relations, ground_truth : str or Path, optional
        Files to evaluate against (default: module docstring of :class:`LogData`).
    """
    import time
    from dataclasses import replace

    from slam.extraction import iter_scan_lines
    from slam.inputs import open_log

    scanner = scanner if scanner is not None else ScannerConfig()
    if odometry_sign is not None:
        scanner = replace(scanner, odometry_sign=odometry_sign)  # type: ignore[arg-type]
    opened = open_log(str(source), scanner, max_scans=max_scans)
    scans: list[Scan] = []
    lines: list[list[Line]] = []
    t0 = time.perf_counter()

    def limited() -> Iterator[Scan]:
        for scan in opened.scans(max_scans):
            scans.append(scan)
            yield scan

    for _scan, fitted in iter_scan_lines(limited(), linefit_config):
        lines.append(list(fitted))
        if progress is not None and len(lines) % 100 == 0:
            progress(len(lines))
    t_extract = time.perf_counter() - t0  # includes reading (streamed together)
    if not scans:
        raise DatasetError(f"{opened.log}: no laser scans in the log")
    folder = opened.log.parent
    gt = Path(ground_truth) if ground_truth is not None else folder / "ground_truth.tum"
    rel = Path(relations) if relations is not None else opened.relations
    if rel is None and (folder / "relations.txt").is_file():
        rel = folder / "relations.txt"  # a `lineslam simulate` folder
    return LogData(
        name=opened.name,
        log_path=Path(opened.log),
        scans=scans,
        lines=lines,
        relations_path=rel,
        ground_truth_path=gt if gt.is_file() else None,
        extraction_s=t_extract,
        policy=opened.policy,
    )


# Bump when what a cache file holds changes meaning (2: max-range readings excluded;
# 4: the input policy, any log format).
_CACHE_VERSION = 4


def _cache_key(
    source: str | Path,
    linefit_config: LineFitConfig,
    max_scans: int | None,
    odometry_sign: str | None,
    scanner: ScannerConfig | None,
    relations: str | Path | None,
    ground_truth: str | Path | None,
) -> str:
    from slam.io import resolve_log
    from slam.io.rosbag import is_rosbag

    log = Path(source) if is_rosbag(source) else Path(resolve_log(str(source)).log)
    stat = log.stat()
    text = (
        to_toml_string(config_to_dict(linefit_config))
        + to_toml_string(config_to_dict(scanner or ScannerConfig()))
        + f"{_CACHE_VERSION}|{log.resolve()}|{stat.st_size}|{stat.st_mtime_ns}|{max_scans}"
        + f"|{odometry_sign}|{relations}|{ground_truth}"
    )
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def cached_log_data(
    source: str | Path,
    linefit_config: LineFitConfig,
    cache_dir: Path | None,
    max_scans: int | None = None,
    odometry_sign: str | None = None,
    scanner: ScannerConfig | None = None,
    relations: str | Path | None = None,
    ground_truth: str | Path | None = None,
) -> LogData:
    """:func:`load_log` through a pickle cache in ``cache_dir`` (keyed by log and config)."""
    kwargs: dict[str, Any] = {
        "odometry_sign": odometry_sign,
        "scanner": scanner,
        "relations": relations,
        "ground_truth": ground_truth,
    }
    if cache_dir is None:
        return load_log(source, linefit_config, max_scans, **kwargs)
    key = _cache_key(source, linefit_config, max_scans, **kwargs)
    path = Path(cache_dir) / f"lines-{key}.pkl"
    if path.is_file():
        with path.open("rb") as fh:
            data: Any = pickle.load(fh)
        if isinstance(data, LogData):
            return data
    data = load_log(source, linefit_config, max_scans, **kwargs)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    with tmp.open("wb") as fh:
        pickle.dump(data, fh, protocol=pickle.HIGHEST_PROTOCOL)
    tmp.replace(path)
    return data
