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
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from linefit.config import LineFitConfig
from linefit.line import Line
from linefit.tomlconfig import config_to_dict, to_toml_string
from slam.errors import DatasetError
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
        Relations file of the log: the catalogue's, or ``relations.txt`` beside the log.
    ground_truth_path : Path or None
        ``ground_truth.tum`` next to a simulated log, if present.
    extraction_s : float
        Time spent extracting lines.
    """

    name: str
    log_path: Path
    scans: list[Scan]
    lines: list[list[Line]]
    relations_path: Path | None
    ground_truth_path: Path | None
    extraction_s: float

    @property
    def n_points(self) -> int:
        """Valid range readings over all scans."""
        return int(sum(int(s.valid_mask().sum()) for s in self.scans))


def load_log(
    source: str | Path,
    linefit_config: LineFitConfig,
    max_scans: int | None = None,
    progress: Callable[[int], None] | None = None,
    odometry_sign: str = "velocity",
) -> LogData:
    """Read a log and extract every scan's lines.

    Parameters
    ----------
    source : str or Path
        A log file or a registered dataset name (``intel``, ``aces``, ``fr079``).
    linefit_config : LineFitConfig
    max_scans : int, optional
        Read only the first scans.
    progress : callable, optional
        Called with the number of scans read so far (every 100 scans).
    odometry_sign : {"velocity", "logged"}
        Which odometry (``SlamConfig.odometry_sign``, :func:`slam.io.carmen.iter_log_scans`).
    """
    import time

    from slam.extraction import iter_scan_lines
    from slam.io import resolve_log
    from slam.io.carmen import iter_log_scans

    resolved = resolve_log(str(source))
    scans: list[Scan] = []
    lines: list[list[Line]] = []
    t0 = time.perf_counter()

    def limited() -> Iterator[Scan]:
        for scan in iter_log_scans(resolved.log, odometry_sign):
            if max_scans is not None and len(scans) >= max_scans:
                return
            scans.append(scan)
            yield scan

    for _scan, fitted in iter_scan_lines(limited(), linefit_config):
        lines.append(list(fitted))
        if progress is not None and len(lines) % 100 == 0:
            progress(len(lines))
    t_extract = time.perf_counter() - t0  # includes reading (streamed together)
    if not scans:
        raise DatasetError(f"{resolved.log}: no laser scans in the log")
    gt = resolved.log.parent / "ground_truth.tum"
    relations = resolved.relations
    if relations is None and (resolved.log.parent / "relations.txt").is_file():
        relations = resolved.log.parent / "relations.txt"  # a `lineslam simulate` folder
    return LogData(
        name=resolved.name,
        log_path=Path(resolved.log),
        scans=scans,
        lines=lines,
        relations_path=relations,
        ground_truth_path=gt if gt.is_file() else None,
        extraction_s=t_extract,
    )


# Bump when what a cache file holds changes meaning (2: max-range readings excluded).
_CACHE_VERSION = 3


def _cache_key(
    source: str | Path, linefit_config: LineFitConfig, max_scans: int | None, odometry_sign: str
) -> str:
    from slam.io import resolve_log

    log = Path(resolve_log(str(source)).log)
    stat = log.stat()
    text = (
        to_toml_string(config_to_dict(linefit_config))
        + f"{_CACHE_VERSION}|{log.resolve()}|{stat.st_size}|{stat.st_mtime_ns}|{max_scans}"
        + f"|{odometry_sign}"
    )
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def cached_log_data(
    source: str | Path,
    linefit_config: LineFitConfig,
    cache_dir: Path | None,
    max_scans: int | None = None,
    odometry_sign: str = "velocity",
) -> LogData:
    """:func:`load_log` through a pickle cache in ``cache_dir`` (keyed by log and config)."""
    if cache_dir is None:
        return load_log(source, linefit_config, max_scans, odometry_sign=odometry_sign)
    key = _cache_key(source, linefit_config, max_scans, odometry_sign)
    path = Path(cache_dir) / f"lines-{key}.pkl"
    if path.is_file():
        with path.open("rb") as fh:
            data: Any = pickle.load(fh)
        if isinstance(data, LogData):
            return data
    data = load_log(source, linefit_config, max_scans, odometry_sign=odometry_sign)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    with tmp.open("wb") as fh:
        pickle.dump(data, fh, protocol=pickle.HIGHEST_PROTOCOL)
    tmp.replace(path)
    return data
