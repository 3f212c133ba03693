"""Occupancy grids ray-traced from scans at estimated poses, written in map_server form.

Main entry points::

    grid = occupancy_grid(poses_world_laser, scans, resolution_m=0.05)
    write_map_server(grid, "out/map")        # out/map.pgm + out/map.yaml
    read_map_server("out/map.yaml") -> (image uint8 (rows, cols), metadata dict)

Ray tracing
-----------
Each beam that measures a surface (finite, > 0, below the scan's range limit) counts a *hit*
in the cell of its end point and a *miss* in every cell its ray crosses before it (sampled
every half cell from the laser).  No-return beams count nothing.  A cell's occupancy
probability combines its counts in log-odds, as GMapping's and Cartographer's grids do:
``l = hits·logit(P_HIT) + misses·logit(P_MISS)`` with ``P_HIT = 0.7`` and ``P_MISS = 0.4``
(a hit counts about twice a miss: a ray grazing a wall crosses its cell more often than it
ends there), ``p = 1 / (1 + exp(−l))``; a cell no ray touched is unknown.

The map_server form (ROS ``map_server`` / ``nav2_map_server``)
--------------------------------------------------------------
``NAME.pgm``: binary greyscale (P5), row 0 at the top (largest y), as ``map_saver`` writes
it: 0 (black) occupied (``p > occupied_thresh``), 254 free (``p < free_thresh``), 205
unknown.  ``NAME.yaml``::

    image: NAME.pgm
    resolution: 0.05          # m per cell
    origin: [x, y, 0.0]       # world pose of the lower-left cell's corner (m, m, rad)
    negate: 0
    occupied_thresh: 0.65
    free_thresh: 0.196

With ``negate: 0`` map_server reads a pixel ``v`` as occupancy ``(255 − v) / 255``: 0 → 1.0
(occupied), 254 → 0.004 (free), 205 → 0.196 (neither: unknown), so the file means what the
thresholds above decided.  The world frame is the run's (the first laser pose).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slam import interrupts
from slam.errors import InputError, LogFormatError
from slam.types import Scan

__all__ = [
    "FREE",
    "OCCUPIED",
    "UNKNOWN",
    "OccupancyGrid",
    "map_server_paths",
    "occupancy_grid",
    "read_map_server",
    "write_map_server",
]

FloatArray = NDArray[np.float64]

P_HIT = 0.7
"""Probability that a cell with a beam's end point in it is occupied (one hit)."""
P_MISS = 0.4
"""Probability that a cell a beam passed through is occupied (one miss)."""

OCCUPIED = 0
FREE = 254
UNKNOWN = 205
_MAX_SAMPLES = 1_000_000  # ray samples per batch (memory; ~0.2 s, signals checked between)


@dataclass(frozen=True, eq=False)
class OccupancyGrid:
    """Hit and miss counts on a regular grid.

    Attributes
    ----------
    hits, misses : ndarray of int, shape (rows, cols)
        Row ``i`` covers ``y ∈ [origin_y + i·res, origin_y + (i+1)·res)`` (row 0 at the
        bottom), column ``j`` likewise in x.
    resolution_m : float
        Cell size (m).
    origin_xy : tuple of 2 floats
        World coordinates (m) of the lower-left corner of cell ``(0, 0)``.
    """

    hits: NDArray[np.int64]
    misses: NDArray[np.int64]
    resolution_m: float
    origin_xy: tuple[float, float]

    @property
    def shape(self) -> tuple[int, int]:
        """``(rows, cols)``."""
        return (int(self.hits.shape[0]), int(self.hits.shape[1]))

    def probability(self) -> FloatArray:
        """Occupancy probability per cell (module docstring; NaN where no ray passed)."""
        logit = (
            np.log(P_HIT / (1 - P_HIT)) * self.hits + np.log(P_MISS / (1 - P_MISS)) * self.misses
        )
        p = 1.0 / (1.0 + np.exp(-np.clip(logit, -50.0, 50.0)))
        return np.where(self.hits + self.misses > 0, p, np.nan)

    def image(self, occupied_thresh: float = 0.65, free_thresh: float = 0.196) -> NDArray[np.uint8]:
        """The map_saver image (module docstring), row 0 at the top."""
        p = self.probability()
        out = np.full(p.shape, UNKNOWN, dtype=np.uint8)
        known = np.isfinite(p)
        out[known & (p > occupied_thresh)] = OCCUPIED
        out[known & (p < free_thresh)] = FREE
        return out[::-1].copy()

    def cell_of(self, xy: FloatArray) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """``(row, col)`` of world points ``(n, 2)`` (row 0 at the bottom)."""
        ij = np.floor((np.asarray(xy, float) - np.asarray(self.origin_xy)) / self.resolution_m)
        return ij[:, 1].astype(np.intp), ij[:, 0].astype(np.intp)


def _rays(
    poses_world_laser: FloatArray, scans: Sequence[Scan]
) -> tuple[FloatArray, FloatArray, NDArray[np.intp]]:
    """Origins ``(S, 2)``, end points ``(B, 2)`` and the scan of each valid beam ``(B,)``."""
    origins = np.asarray(poses_world_laser, dtype=float)[:, :2]
    ends: list[FloatArray] = []
    owner: list[NDArray[np.intp]] = []
    for k, (pose, scan) in enumerate(zip(poses_world_laser, scans, strict=True)):
        mask = scan.valid_mask()
        r, b = scan.ranges[mask], scan.bearings[mask] + pose[2]
        ends.append(np.column_stack([pose[0] + r * np.cos(b), pose[1] + r * np.sin(b)]))
        owner.append(np.full(r.shape[0], k, dtype=np.intp))
    if not ends:
        return origins, np.zeros((0, 2)), np.zeros(0, np.intp)
    return origins, np.concatenate(ends), np.concatenate(owner)


def occupancy_grid(
    poses_world_laser: FloatArray,
    scans: Sequence[Scan],
    resolution_m: float = 0.05,
    margin_m: float = 1.0,
) -> OccupancyGrid:
    """Ray-trace ``scans`` at their laser poses into a grid (module docstring).

    Parameters
    ----------
    poses_world_laser : ndarray, shape (S, 3)
        The laser pose of each scan in the world frame.
    scans : sequence of Scan
        Their ranges, bearings and range limits.
    resolution_m : float
        Cell size (m, > 0).
    margin_m : float
        Unknown border around everything the rays reach (m).
    """
    if not (np.isfinite(resolution_m) and resolution_m > 0.0):
        raise InputError(f"resolution must be > 0 m, got {resolution_m!r}")
    poses = np.asarray(poses_world_laser, dtype=float).reshape(-1, 3)
    if poses.shape[0] != len(scans) or poses.shape[0] == 0:
        raise InputError(f"need one pose per scan (got {poses.shape[0]} and {len(scans)})")
    if not np.isfinite(poses).all():
        raise InputError("poses must be finite")
    origins, ends, owner = _rays(poses, scans)
    pts = np.vstack([origins, ends])
    lo = np.floor((pts.min(axis=0) - margin_m) / resolution_m) * resolution_m
    hi = pts.max(axis=0) + margin_m
    cols, rows = (np.ceil((hi - lo) / resolution_m).astype(int) + 1).tolist()
    if rows * cols > 400_000_000:
        raise InputError(
            f"the grid would have {rows} x {cols} cells at {resolution_m} m: choose a coarser "
            "resolution"
        )
    hits = np.zeros(rows * cols, dtype=np.int64)
    misses = np.zeros(rows * cols, dtype=np.int64)
    step = 0.5 * resolution_m

    def flat(xy: FloatArray) -> NDArray[np.intp]:
        ij = np.floor((xy - lo) / resolution_m).astype(np.intp)
        return ij[:, 1] * cols + ij[:, 0]

    hits += np.bincount(flat(ends), minlength=rows * cols) if ends.shape[0] else 0
    start = origins[owner]
    length = np.hypot(*(ends - start).T)
    n_samples = np.maximum(np.floor((length - step) / step).astype(np.intp), 0)
    first = 0
    while first < ends.shape[0]:
        interrupts.check()  # between chunks of rays (slam.interrupts)
        counts = np.cumsum(n_samples[first:])
        last = first + max(int(np.searchsorted(counts, _MAX_SAMPLES)), 1)
        last = min(last, ends.shape[0])
        n = n_samples[first:last]
        ray = np.repeat(np.arange(first, last), n)
        k = np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n)
        t = ((k + 1) * step / np.maximum(length[ray], 1e-12))[:, None]
        xy = start[ray] + t * (ends[ray] - start[ray])
        cells = flat(xy)
        # a ray marks each cell it crosses once (a straight ray leaves a cell for good, so
        # repeated samples are neighbours), and never its own end cell
        new = np.ones(cells.shape[0], dtype=bool)
        new[1:] = (cells[1:] != cells[:-1]) | (ray[1:] != ray[:-1])
        new &= cells != flat(ends[ray])
        misses += np.bincount(cells[new], minlength=rows * cols)
        first = last
    return OccupancyGrid(
        hits.reshape(rows, cols),
        misses.reshape(rows, cols),
        float(resolution_m),
        (float(lo[0]), float(lo[1])),
    )


def map_server_paths(path: str | Path) -> tuple[Path, Path]:
    """``(PATH.pgm, PATH.yaml)`` for ``path`` with or without one of those suffixes."""
    base = Path(path)
    if base.suffix in (".yaml", ".pgm"):
        base = base.with_suffix("")
    return base.with_suffix(".pgm"), base.with_suffix(".yaml")


def write_map_server(
    grid: OccupancyGrid,
    path: str | Path,
    *,
    occupied_thresh: float = 0.65,
    free_thresh: float = 0.196,
    into: tuple[Path, Path] | None = None,
) -> tuple[Path, Path]:
    """Write ``PATH.pgm`` and ``PATH.yaml`` (``path`` with or without a suffix); return both.

    ``into``: write the two files there instead (temporary files renamed into place later,
    :func:`slam.io.atomic.staged_files`); the YAML still names ``PATH.pgm``.
    """
    if not 0.0 <= free_thresh < occupied_thresh <= 1.0:
        raise InputError("need 0 <= free_thresh < occupied_thresh <= 1")
    pgm, yaml = map_server_paths(path)
    pgm_file, yaml_file = into if into is not None else (pgm, yaml)
    image = grid.image(occupied_thresh, free_thresh)
    rows, cols = image.shape
    header = f"P5\n# lineslam occupancy grid, {grid.resolution_m} m/cell\n{cols} {rows}\n255\n"
    pgm_file.write_bytes(header.encode("ascii") + image.tobytes())
    x0, y0 = grid.origin_xy
    yaml_file.write_text(
        f"image: {pgm.name}\n"
        f"resolution: {grid.resolution_m!r}\n"
        f"origin: [{x0!r}, {y0!r}, 0.0]\n"
        "negate: 0\n"
        f"occupied_thresh: {occupied_thresh!r}\n"
        f"free_thresh: {free_thresh!r}\n",
        encoding="utf-8",
    )
    return pgm, yaml


def read_map_server(path: str | Path) -> tuple[NDArray[np.uint8], dict[str, Any]]:
    """Read a map_server YAML (the keys above) and its P5 image: ``(image, metadata)``."""
    yaml_path = Path(path)
    meta: dict[str, Any] = {}
    for line in yaml_path.read_text(encoding="utf-8").splitlines():
        key, sep, value = line.partition(":")
        if not sep or not key.strip() or key.strip().startswith("#"):
            continue
        value = value.strip()
        if value.startswith("["):
            meta[key.strip()] = [float(v) for v in value.strip("[]").split(",")]
        else:
            try:
                meta[key.strip()] = float(value)
            except ValueError:
                meta[key.strip()] = value
    if "image" not in meta:
        raise LogFormatError("no 'image' key", str(yaml_path))
    data = (yaml_path.parent / str(meta["image"])).read_bytes()
    tokens: list[bytes] = []
    pos = 0
    while len(tokens) < 4:
        while data[pos : pos + 1].isspace():
            pos += 1
        if data[pos : pos + 1] == b"#":
            pos = data.index(b"\n", pos) + 1
            continue
        end = pos
        while not data[end : end + 1].isspace():
            end += 1
        tokens.append(data[pos:end])
        pos = end
    if tokens[0] != b"P5":
        raise LogFormatError("not a binary PGM (P5)", str(meta["image"]))
    cols, rows = int(tokens[1]), int(tokens[2])
    pixels = np.frombuffer(data[pos + 1 : pos + 1 + rows * cols], dtype=np.uint8)
    return pixels.reshape(rows, cols).copy(), meta


def select_scans(poses: FloatArray, min_distance_m: float, min_angle_rad: float) -> list[int]:
    """Indices of poses that moved at least this far (or turned this much) since the last kept."""
    keep = [0] if len(poses) else []
    for k in range(1, len(poses)):
        d = poses[k] - poses[keep[-1]]
        turn = abs((d[2] + np.pi) % (2 * np.pi) - np.pi)
        if np.hypot(d[0], d[1]) >= min_distance_m or turn >= min_angle_rad:
            keep.append(k)
    return keep


def scans_at_poses(scans: Iterable[Scan], keep: Sequence[int]) -> list[Scan]:
    """The scans at the positions ``keep`` (sorted) of an iterable, read once."""
    wanted = set(keep)
    return [s for k, s in enumerate(scans) if k in wanted]
