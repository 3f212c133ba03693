"""Runner of ``lineslam map``: read a log, fit every scan, merge across poses, write results.

The poses are the log's own estimates (CARMEN: the laser pose logged with each scan, i.e. the
odometry, as logged; a bag: the base odometry composed with the laser mounting,
:mod:`slam.inputs`), each with the fixed covariance of ``[map]`` (``pose_sigma_xy_m``,
``pose_sigma_theta_rad``).  Results folder (INTERFACES.md): ``map.json`` (world = the log's
odometry frame), ``summary.json`` (with the log's anomalies, ``log_anomalies``),
``config.toml`` and, unless disabled, figures in the style of the paper's Figs. 3-8 under
``figures/``.  The folder is written into a temporary folder and put in place whole when
complete (:func:`slam.io.atomic.staged_dir`).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from linefit.line import Line
from slam import interrupts
from slam.config import RunConfig
from slam.errors import InputError
from slam.geometry import pose_compose
from slam.inputs import InputPolicy, LogInput
from slam.lines.mapbuilder import LineMap, MapBuilder
from slam.lines.mapio import write_map_json
from slam.lines.transform import line_to_world
from slam.types import Scan

__all__ = [
    "MapRun",
    "build_map",
    "compression",
    "fit_scan",
    "run_map",
    "simulate_paper_sequence",
    "write_map_results",
]

if TYPE_CHECKING:
    from slam.diagnostics import WarningTally

FloatArray = NDArray[np.float64]


def compression(points: int, two_point_items: int) -> float:
    """``1 − 2·items/points``: the paper's compression, a line (segment) counting as 2 points."""
    return float(1.0 - 2.0 * two_point_items / points) if points > 0 else 0.0


def valid_beams(scan: Scan, config: RunConfig) -> NDArray[np.bool_]:
    """Beams that measure a surface: finite, > 0, below the max range (reading note 6)."""
    mask = scan.valid_mask()
    if config.linefit.max_range_m is not None:
        mask &= scan.ranges < config.linefit.max_range_m
    return mask


def fit_scan(scan: Scan, config: RunConfig) -> tuple[list[Line], int]:
    """Lines of one scan (laser frame) and the number of points that could enter a fit."""
    from slam.extraction import extract_scan_lines

    n_points = int(np.count_nonzero(valid_beams(scan, config)))
    return extract_scan_lines(scan, config.linefit), n_points


_LOG_POSES = InputPolicy()
"""The log's own poses: the logged laser pose, else the base's (no mounting)."""


def scan_pose(scan: Scan, policy: InputPolicy | None = None) -> FloatArray | None:
    """The laser pose of ``scan`` in the log's odometry frame, or None if it has no pose.

    Read by the input policy (:meth:`slam.inputs.InputPolicy.pose_odom_laser`); the default
    takes the log's own poses (``pose_odom_laser``, else ``pose_odom_base``).

    Raises
    ------
    InputError
        The pose is not finite.
    """
    if scan.pose_odom_laser is None and scan.pose_odom_base is None:
        return None
    return (policy or _LOG_POSES).pose_odom_laser(scan)


@dataclass
class _FigureData:
    """What the figures need, collected while mapping (bounded in size)."""

    max_ellipse_scans: int = 10
    ellipse_every: int = 30
    points: list[FloatArray] = field(default_factory=list)
    ellipse_centers: list[FloatArray] = field(default_factory=list)
    ellipse_covs: list[FloatArray] = field(default_factory=list)
    fit_r_alpha: list[FloatArray] = field(default_factory=list)
    fit_cov: list[FloatArray] = field(default_factory=list)
    fit_segments: list[FloatArray] = field(default_factory=list)

    def add(
        self,
        scan: Scan,
        mask: NDArray[np.bool_],
        pose: FloatArray,
        lines: list[Line],
        config: RunConfig,
    ) -> None:
        d, phi = scan.ranges[mask], scan.bearings[mask]
        pts = np.column_stack([d * np.cos(phi), d * np.sin(phi), np.zeros_like(d)])
        world = pose_compose(np.broadcast_to(pose, pts.shape), pts)[:, :2]
        self.points.append(world.astype(np.float32))
        if len(self.ellipse_centers) < self.max_ellipse_scans:
            sel = slice(0, None, self.ellipse_every)
            noise = config.linefit.noise
            ds, ps = d[sel], phi[sel] + pose[2]
            sd = noise.sigma_range_m + noise.sigma_range_per_m * ds
            c, s = np.cos(ps), np.sin(ps)
            # Eq. 8 rotated into the world
            Q = (ds**2 * noise.sigma_bearing_rad**2)[:, None, None] * np.stack(
                [np.stack([s * s, -s * c], -1), np.stack([-s * c, c * c], -1)], -2
            ) + (sd**2)[:, None, None] * np.stack(
                [np.stack([c * c, s * c], -1), np.stack([s * c, s * s], -1)], -2
            )
            self.ellipse_centers.append(world[sel])
            self.ellipse_covs.append(Q)
        if lines:
            x = np.array([[ln.r, ln.alpha, ln.s] for ln in lines])
            P = np.stack([ln.cov for ln in lines])
            xw, Pw = line_to_world(x, P, pose)
            self.fit_r_alpha.append(xw[:, :2])
            self.fit_cov.append(Pw[:, :2, :2])
            for ln in lines:
                ends = np.stack([ln.point_at(seg) for seg in ln.segments_s])  # (k, 2, 2)
                e3 = np.concatenate([ends, np.zeros((*ends.shape[:-1], 1))], -1)
                self.fit_segments.append(pose_compose(np.broadcast_to(pose, e3.shape), e3)[..., :2])


@dataclass
class MapRun:
    """Result of :func:`build_map`."""

    line_map: LineMap
    summary: dict[str, Any]
    figures: _FigureData | None


def build_map(
    scans: Iterable[Scan],
    config: RunConfig,
    *,
    max_scans: int | None = None,
    collect_figures: bool = True,
    progress: Callable[[int], None] | None = None,
    fit: Callable[[Scan, RunConfig], tuple[list[Line], int]] | None = None,
    pose_covs: Sequence[FloatArray] | None = None,
    policy: InputPolicy | None = None,
) -> MapRun:
    """Fit every scan and merge its lines into a map with the scans' own poses.

    Parameters
    ----------
    scans : iterable of Scan
        In log order; each needs ``pose_odom_laser`` or ``pose_odom_base``.  Scans without
        any pose are skipped and counted (``scans_without_pose``).
    config : RunConfig
        ``linefit`` (fitting) and ``map`` (merging, pose covariance) tables are used.
    max_scans : int, optional
        Stop after this many scans.
    collect_figures : bool
        Keep what the figures need (points, ellipses, fitted lines).
    progress : callable, optional
        Called with 1 after every scan.
    fit : callable, optional
        ``fit(scan, config) -> (lines, n_points)``; default :func:`fit_scan`
        (:func:`slam.extraction.extract_scan_lines`).
    pose_covs : sequence of ndarray (3, 3), optional
        One pose covariance per scan (right perturbation), e.g. odometry compounded from the
        first pose; default ``config.map.pose_cov`` for every scan.
    policy : InputPolicy, optional
        Reads each scan's laser pose (:func:`scan_pose`); default the log's own poses.
    """
    fit_fn = fit_scan if fit is None else fit
    builder = MapBuilder(config.map)
    figures = _FigureData() if collect_figures else None
    n_scans = n_points = n_lines = skipped = 0
    t_fit = t_merge = 0.0
    t0 = time.perf_counter()
    for scan in scans:
        interrupts.check()  # between scans (slam.interrupts)
        if max_scans is not None and n_scans + skipped >= max_scans:
            break
        pose = scan_pose(scan, policy)
        if pose is None:
            skipped += 1
            continue
        t1 = time.perf_counter()
        lines, pts = fit_fn(scan, config)
        t2 = time.perf_counter()
        k = n_scans + skipped
        P = config.map.pose_cov if pose_covs is None else pose_covs[k]
        builder.add_scan(lines, pose, P)
        t3 = time.perf_counter()
        t_fit += t2 - t1
        t_merge += t3 - t2
        n_scans += 1
        n_points += pts
        n_lines += len(lines)
        if figures is not None:
            figures.add(scan, valid_beams(scan, config), pose, lines, config)
        if progress is not None:
            progress(1)
    total = time.perf_counter() - t0
    interrupts.check()
    line_map = builder.line_map()
    st = builder.stats
    summary: dict[str, Any] = {
        "scans": n_scans,
        "points": n_points,
        "lines_fit": n_lines,
        "lines_merged": len(line_map),
        "segments_merged": line_map.n_segments,
        "compression": compression(n_points, line_map.n_segments),
        "compression_lines": compression(n_points, len(line_map)),
        "compression_fit": compression(n_points, n_lines),
        "scans_without_pose": skipped,
        "candidate_pairs_tested": st.candidate_pairs_tested,
        "pairs_in_gate": st.pairs_in_gate,
        "fusions": st.fusions,
        "runtime_s": {"fit": t_fit, "merge": t_merge, "read_and_other": total - t_fit - t_merge},
        "frame": "laser",
        "map_frame": "world (the log's odometry frame)",
        "pose_source": "log (pose_odom_laser, else pose_odom_base)",
    }
    return MapRun(line_map, summary, figures)


def _write_map_files(out: Path, run: MapRun, title: str, plot: bool) -> dict[str, Path]:
    """Write ``map.json`` and the figures (their time goes to ``runtime_s["plot"]``)."""
    paths = {"map": write_map_json(out / "map.json", run.line_map)}
    interrupts.check()
    if plot and run.figures is not None:
        t0 = time.perf_counter()
        paths.update(_draw(out / "figures", run, title))
        run.summary["runtime_s"]["plot"] = time.perf_counter() - t0
    return paths


def write_map_results(
    out: Path, run: MapRun, title: str = "", plot: bool = True
) -> dict[str, Path]:
    """Write ``map.json``, ``summary.json`` and the figures into ``out`` (which must exist)."""
    from slam.io.results import write_summary

    paths = _write_map_files(out, run, title, plot)
    paths["summary"] = write_summary(out, run.summary)
    return paths


def _draw(folder: Path, run: MapRun, title: str) -> dict[str, Path]:
    from slam.plotting import map as plotting_map

    fig = run.figures
    assert fig is not None
    folder.mkdir(parents=True, exist_ok=True)
    pts = np.concatenate(fig.points) if fig.points else np.zeros((0, 2))
    centers = np.concatenate(fig.ellipse_centers) if fig.ellipse_centers else np.zeros((0, 2))
    covs = np.concatenate(fig.ellipse_covs) if fig.ellipse_covs else np.zeros((0, 2, 2))
    ra = np.concatenate(fig.fit_r_alpha) if fig.fit_r_alpha else np.zeros((0, 2))
    cv = np.concatenate(fig.fit_cov) if fig.fit_cov else np.zeros((0, 2, 2))
    lm = run.line_map
    merged = (
        lm.r_alpha(),
        np.array([ln.cov_r_alpha for ln in lm.lines]).reshape(-1, 2, 2),
        [ln.segments for ln in lm.lines],
    )
    path = plotting_map.figure_panels(
        folder / "map_panels.png", pts, centers, covs, (ra, cv, fig.fit_segments), merged, title
    )
    return {"figure": path}


def run_map(
    log: str | Path | LogInput,
    out: Path,
    config: RunConfig,
    *,
    plot: bool = True,
    max_scans: int | None = None,
    progress: Callable[[int], None] | None = None,
    tally: WarningTally | None = None,
    strict: bool = False,
) -> dict[str, Any]:
    """``lineslam map``: open ``log`` (:func:`slam.inputs.open_log`), build the map, write.

    The poses are the logged laser poses with the odometry as logged (no sign repair), or,
    where a scan has no laser pose (bags), the base odometry composed with the mounting.
    ``config`` is written as ``config.toml``; the log's anomalies are counted in
    ``summary.json`` (a CARMEN log; ``strict``: the first one is an error).

    Raises
    ------
    InputError
        The log has no laser scans with a pose, or a malformed line.
    OutputError
        ``out`` cannot be written, or is or holds the log.
    """
    from contextlib import nullcontext

    from slam.config import check_run_config, open_run_log
    from slam.diagnostics import tally_warnings
    from slam.io.atomic import staged_dir
    from slam.io.carmen import CarmenStats
    from slam.io.results import write_summary

    config = check_run_config(config)
    source = log if isinstance(log, LogInput) else open_run_log(log, config, max_scans=max_scans)
    source.policy = replace(
        source.policy, laser_odometry="logged", odometry_sign="logged", output_frame="laser"
    )
    stats = CarmenStats(path=str(source.log))
    with (
        nullcontext(tally) if tally is not None else tally_warnings() as tallied,
        staged_dir(out, inputs=[source.log]) as work,
    ):
        config.to_toml(work / "config.toml")
        t0 = time.perf_counter()
        run = build_map(
            source.scans(max_scans, stats=stats, strict=strict),
            config,
            max_scans=max_scans,
            collect_figures=plot,
            progress=progress,
            policy=source.policy,
        )
        if run.summary["scans"] == 0:
            odometry = f" ({stats.odometry} ODOM messages)" if stats.odometry else ""
            without = run.summary["scans_without_pose"]
            what = (
                f"no laser scans with a pose ({without} without)" if without else "no laser scans"
            )
            raise InputError(f"the log contains {what}{odometry}", str(source.log))
        run.summary.update(source.run_summary(run.summary["scans"], max_scans))
        t1 = time.perf_counter()
        title = f"{source.name}: {run.summary['scans']} scans"
        _write_map_files(work, run, title=title, plot=plot)
        run.summary["runtime_s"]["write"] = time.perf_counter() - t1
        run.summary["runtime_s"]["total"] = time.perf_counter() - t0
        run.summary["warnings"] = tallied.as_list()
        run.summary["log_anomalies"] = stats.anomalies.to_dict()
        write_summary(work, run.summary)
    return run.summary


PAPER_SPACING_M = {"hallway": 3.5, "lab": 2.4}
"""Distance (m) between the poses of a paper-style sequence along the world's path."""


def simulate_paper_sequence(
    world_name: str,
    n_poses: int,
    rng: np.random.Generator,
    pose_cov: str = "step",
    n_beams: int = 720,
    sigma_range_m: float = 0.005,
    sigma_bearing_rad: float = 1e-4,
) -> tuple[list[Scan], list[FloatArray]]:
    """A sequence like the paper's Sec. VI: ``n_poses`` scans along a simulated world's path.

    The paper's sensor (720 beams, 0.25° over 180°; the ray is cast at ``Φ + ε_φ`` and reported
    at ``Φ``, range noise ``ε_d``), poses ``PAPER_SPACING_M`` apart along the world's path
    (:mod:`slam.sim`), odometry with the simulator's default noise between them.

    Parameters
    ----------
    world_name : str
        ``"hallway"`` or ``"lab"`` (or any :func:`slam.sim.get_world` name).
    n_poses : int
    rng : numpy.random.Generator
    pose_cov : {"step", "chain"}
        Each scan's pose covariance: the odometry step from the previous scan, i.e. the
        uncertainty relative to the map built around it (default), or the odometry compounded
        from the first scan (the paper's ``P^1j``; far poses then merge too eagerly).

    Returns
    -------
    scans : list of Scan
        ``pose_odom_laser`` is the odometry estimate; readings with no hit are at 80 m (max).
    covs : list of ndarray (3, 3)
        Pose covariance of each scan (right perturbation).
    """
    from slam.lines.transform import compose_chain
    from slam.sim import (
        cast_scan,
        get_world,
        motion_noise_covariance,
        noisy_motions,
        relative_motions,
        trajectory_from_waypoints,
    )
    from slam.sim.config import OdometryNoiseConfig, TrajectoryConfig

    if pose_cov not in ("step", "chain"):
        raise ValueError(f"pose_cov must be 'step' or 'chain', got {pose_cov!r}")
    world = get_world(world_name)
    if world.waypoints is None:
        raise InputError(f"world {world_name!r} has no default path (waypoints)")
    traj = trajectory_from_waypoints(world.waypoints, TrajectoryConfig(scan_spacing_m=0.05))
    path = traj.poses_world_base
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(path[:, :2], axis=0).T))])
    targets = 1.0 + PAPER_SPACING_M.get(world_name, 3.0) * np.arange(n_poses)
    truth = path[np.minimum(np.searchsorted(arc, targets), len(path) - 1)]
    odo = OdometryNoiseConfig()
    motions = relative_motions(truth)
    step_covs = motion_noise_covariance(motions, odo)
    est, chain_covs = compose_chain(noisy_motions(motions, odo, rng), step_covs, truth[0])
    covs = chain_covs if pose_cov == "chain" else np.concatenate([np.zeros((1, 3, 3)), step_covs])
    max_range = 80.0
    bearings = np.asarray(-np.pi / 2 + np.arange(n_beams) * (np.pi / n_beams), dtype=np.float64)
    scans = []
    for k, pose in enumerate(truth):
        jitter = rng.normal(0.0, sigma_bearing_rad, n_beams)
        ranges, _ = cast_scan(pose, bearings + jitter, world, max_range)
        hit = np.isfinite(ranges) & (ranges < max_range)
        ranges = np.where(hit, ranges + rng.normal(0.0, sigma_range_m, n_beams), max_range)
        scans.append(Scan(k, float(k), ranges, bearings, max_range, pose_odom_laser=est[k]))
    return scans, list(covs)
