"""The dataset catalogue (``datasets/catalog.toml``) and the resolution of ``LOG`` arguments.

Main entry points (stable, used across the project)::

    resolve_log(name_or_path, *, data_root=None) -> ResolvedLog   # .log, .relations, .manifest
    load_catalog(path=None) -> dict[str, DatasetManifest]
    manifest_for_path(path) -> DatasetManifest | None
    verify_dataset(manifest, data_root=None) -> DatasetStatus      # present? sha256 intact?

A ``LOG`` argument is either a path to a file, used as it is, or the name of a registered
dataset (``intel``, ``aces``, ``fr079``) resolved under the data root: ``$LINESLAM_DATA`` if
set, else ``<repository>/../shared/datasets``.  A file is recognised as a catalogued log by its
**content** (size, then SHA-256; the hash of a file is computed once while it is unchanged),
never by its name: a renamed copy of ``intel.clf`` is still Intel, and another file named
``intel.clf`` is not.  A recognised log gets its entry's manifest (laser geometry, range
limit, mounting) and relations (beside the file under the catalogue's name, else under the
data root).

The catalogue is ``datasets/catalog.toml`` in the repository (``$LINESLAM_CATALOG`` overrides
it; an installed wheel carries a copy inside the package).
"""

from __future__ import annotations

import hashlib
import math
import os
import tomllib
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any, Literal

from linefit.errors import ConfigError
from linefit.tomlconfig import config_from_dict
from slam.errors import DatasetError
from slam.io.laser import LaserGeometry

__all__ = [
    "DatasetManifest",
    "DatasetStatus",
    "LaserFacts",
    "ResolvedLog",
    "catalog_path",
    "data_root",
    "load_catalog",
    "manifest_for_path",
    "resolve_log",
    "sha256_file",
    "verify_dataset",
]

_REPO_ROOT = Path(__file__).resolve().parents[2]


@dataclass(frozen=True)
class LaserFacts:
    """Laser facts of a dataset (see the comments at the top of ``catalog.toml``)."""

    beams: int
    first_angle_deg: float
    step_deg: float
    max_range_m: float
    range_note: str = ""
    mount_x_m: float = 0.0
    mount_y_m: float = 0.0
    mount_theta_deg: float = 0.0
    mount_applied_in_log: bool = False
    mount_note: str = ""

    def __post_init__(self) -> None:
        if self.beams < 1:
            raise ConfigError(f"beams must be >= 1, got {self.beams}")
        if not (self.step_deg > 0.0 and self.max_range_m > 0.0):
            raise ConfigError("step_deg and max_range_m must be > 0")


@dataclass(frozen=True)
class DatasetManifest:
    """One catalogue entry: files (relative to the data root), checksums and sensor facts.

    ``relations_frame`` is the frame whose poses the relations relate: ``"laser"`` (the laser
    scans' poses, the convention of the public relations) or ``"base"`` (the robot base, the
    laser composed with the inverse of the mounting).  A run on the log reports its trajectory
    in that frame by default (:class:`slam.inputs.ScannerConfig` ``output_frame = "auto"``).
    """

    name: str
    title: str
    log: str
    log_sha256: str
    laser: LaserFacts
    log_bytes: int = 0
    relations: str = ""
    relations_sha256: str = ""
    relations_bytes: int = 0
    message_types: tuple[str, ...] = ()
    scans: int = 0
    odometry_messages: int = 0
    relations_count: int = 0
    first_stamp_s: float = math.nan
    last_stamp_s: float = math.nan
    duration_s: float = math.nan
    stamps_monotonic: bool = True
    backward_steps: int = 0
    authors: str = ""
    notes: str = ""
    relations_frame: Literal["laser", "base"] = "laser"

    def __post_init__(self) -> None:
        if self.relations_frame not in ("laser", "base"):
            raise ConfigError(
                f"relations_frame must be laser or base, got {self.relations_frame!r}"
            )

    def laser_geometry(self) -> LaserGeometry:
        """The beam layout of the log's ``FLASER`` lines, for :func:`slam.io.carmen.iter_scans`."""
        facts = self.laser
        return LaserGeometry(
            first_angle_rad=math.radians(facts.first_angle_deg),
            step_rad=math.radians(facts.step_deg),
            n_beams=facts.beams,
            max_range_m=facts.max_range_m,
            pose_base_laser=(
                facts.mount_x_m,
                facts.mount_y_m,
                math.radians(facts.mount_theta_deg),
            ),
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready copy."""
        from dataclasses import asdict

        out = asdict(self)
        out["message_types"] = list(self.message_types)
        return out


@dataclass(frozen=True)
class ResolvedLog:
    """What a ``LOG`` argument names.

    Attributes
    ----------
    log : Path
        The log file.
    relations : Path or None
        Its relations file, if the catalogue names one and it exists.
    manifest : DatasetManifest or None
        The catalogue entry (``None`` for a log the catalogue does not know).
    name : str
        The dataset name, or the file's stem.
    """

    log: Path
    relations: Path | None
    manifest: DatasetManifest | None
    name: str


@dataclass(frozen=True)
class DatasetStatus:
    """Whether a dataset's files are present and match their checksums."""

    name: str
    log: Path
    present: bool
    intact: bool | None
    problems: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready copy."""
        return {
            "name": self.name,
            "log": str(self.log),
            "present": self.present,
            "intact": self.intact,
            "problems": list(self.problems),
        }


def data_root() -> Path:
    """``$LINESLAM_DATA`` if set, else ``<repository>/../shared/datasets``."""
    env = os.environ.get("LINESLAM_DATA")
    return Path(env) if env else _REPO_ROOT.parent / "shared" / "datasets"


def catalog_path() -> Path:
    """``$LINESLAM_CATALOG``, else ``datasets/catalog.toml`` (or the copy inside the package)."""
    env = os.environ.get("LINESLAM_CATALOG")
    if env:
        return Path(env)
    in_repo = _REPO_ROOT / "datasets" / "catalog.toml"
    if in_repo.is_file():
        return in_repo
    return Path(__file__).with_name("catalog.toml")


@lru_cache(maxsize=8)
def _load_catalog_cached(path: str, mtime_ns: int) -> dict[str, DatasetManifest]:
    try:
        with open(path, "rb") as handle:
            data = tomllib.load(handle)
    except FileNotFoundError:
        raise DatasetError(f"{path}: dataset catalogue not found") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise DatasetError(f"{path}: not a valid TOML catalogue ({exc})") from None
    entries = data.get("datasets", {})
    if not isinstance(entries, dict):
        raise DatasetError(f"{path}: [datasets] must be a table")
    out: dict[str, DatasetManifest] = {}
    for name, entry in entries.items():
        if not isinstance(entry, dict):
            raise DatasetError(f"{path}: [datasets.{name}] must be a table")
        try:
            out[name] = config_from_dict(DatasetManifest, {"name": name, **entry})
        except ConfigError as exc:
            raise DatasetError(f"{path}: [datasets.{name}]: {exc}") from None
    return out


def load_catalog(path: str | Path | None = None) -> dict[str, DatasetManifest]:
    """Read the catalogue: ``{name: DatasetManifest}`` (cached while the file is unchanged)."""
    path = Path(path) if path is not None else catalog_path()
    try:
        mtime = path.stat().st_mtime_ns
    except FileNotFoundError:
        raise DatasetError(f"{path}: dataset catalogue not found") from None
    return _load_catalog_cached(str(path), mtime)


@lru_cache(maxsize=64)
def _sha256_cached(path: str, size: int, mtime_ns: int) -> str:
    return sha256_file(path)


def manifest_for_path(path: str | Path) -> DatasetManifest | None:
    """The catalogue entry whose log or relations file has the content of ``path``, if any.

    Compared by size first and then by SHA-256 (cached per file while its size and
    modification time stay the same); the file's name plays no part.
    """
    p = Path(path)
    try:
        stat = p.stat()
    except OSError:
        return None
    if not p.is_file():
        return None
    digest: str | None = None
    for manifest in load_catalog().values():
        for size, expected in (
            (manifest.log_bytes, manifest.log_sha256),
            (manifest.relations_bytes, manifest.relations_sha256),
        ):
            if not expected or (size and size != stat.st_size):
                continue
            if digest is None:
                digest = _sha256_cached(str(p.resolve()), stat.st_size, stat.st_mtime_ns)
            if digest == expected:
                return manifest
    return None


def _relations_for(log: Path, manifest: DatasetManifest, root: Path | None = None) -> Path | None:
    """The entry's relations file: beside ``log`` under its catalogue name, else the data root's."""
    if not manifest.relations:
        return None
    candidate = log.parent / Path(manifest.relations).name
    if candidate.is_file():
        return candidate
    under_root = (root if root is not None else data_root()) / manifest.relations
    return under_root if under_root.is_file() else None


def resolve_log(name_or_path: str | Path, *, root: str | Path | None = None) -> ResolvedLog:
    """Resolve a ``LOG`` argument to files and, where known, the dataset's manifest.

    Parameters
    ----------
    name_or_path
        An existing file (used as it is), or a catalogue name (``intel``, ``aces``, ``fr079``).
    root
        Data root for names; default :func:`data_root`.

    Raises
    ------
    DatasetError
        Neither an existing file nor a known dataset name, or a known dataset whose log is
        missing under the data root (the message says where it looked).
    """
    candidate = Path(name_or_path)
    if candidate.is_file():
        manifest = manifest_for_path(candidate)
        relations = _relations_for(candidate, manifest) if manifest is not None else None
        name = manifest.name if manifest is not None else candidate.stem
        return ResolvedLog(candidate, relations, manifest, name)
    catalog = load_catalog()
    key = str(name_or_path)
    if key not in catalog:
        if candidate.exists():
            raise DatasetError(f"{candidate}: is not a file")
        raise DatasetError(
            f"{key!r} is neither an existing file nor a registered dataset "
            f"(known: {', '.join(sorted(catalog))})"
        )
    manifest = catalog[key]
    base = Path(root) if root is not None else data_root()
    log = base / manifest.log
    if not log.is_file():
        raise DatasetError(
            f"dataset {key!r}: {log} not found (set LINESLAM_DATA to the folder holding "
            f"{Path(manifest.log).parent}/)"
        )
    relations = base / manifest.relations if manifest.relations else None
    if relations is not None and not relations.is_file():
        relations = None
    return ResolvedLog(log, relations, manifest, key)


def sha256_file(path: str | Path, chunk_bytes: int = 1 << 20) -> str:
    """Hex SHA-256 of a file, read in chunks."""
    digest = hashlib.sha256()
    with Path(path).open("rb") as handle:
        while chunk := handle.read(chunk_bytes):
            digest.update(chunk)
    return digest.hexdigest()


def verify_dataset(
    manifest: DatasetManifest, root: str | Path | None = None, *, checksum: bool = True
) -> DatasetStatus:
    """Check that a dataset's log and relations exist with the catalogue's size and sha256."""
    base = Path(root) if root is not None else data_root()
    files = [(manifest.log, manifest.log_bytes, manifest.log_sha256)]
    if manifest.relations:
        files.append((manifest.relations, manifest.relations_bytes, manifest.relations_sha256))
    problems: list[str] = []
    present = True
    for relative, size, digest in files:
        path = base / relative
        if not path.is_file():
            present = False
            problems.append(f"{path}: missing")
            continue
        if size and path.stat().st_size != size:
            problems.append(f"{path}: {path.stat().st_size} bytes, catalogue says {size}")
        elif checksum and digest and sha256_file(path) != digest:
            problems.append(f"{path}: sha256 differs from the catalogue")
    intact: bool | None = None
    if present:
        intact = not problems if checksum else (None if not problems else False)
    return DatasetStatus(manifest.name, base / manifest.log, present, intact, tuple(problems))
