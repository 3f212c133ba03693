"""A line-level simulator: ground-truth walls, a trajectory, noisy odometry and noisy line fits.

For estimator studies that should not depend on the per-scan extraction (Monte-Carlo
consistency, EKF vs graph on the same measurements), lines are generated directly: every wall
visible from a pose (range limit, occlusion by other walls, sampled along the wall) becomes one
measured line ``(r, α)`` in the laser frame, perturbed by a Gaussian whose covariance is that of
the weighted least-squares fit of points spaced ``point_spacing_m`` along the visible part with
range noise ``sigma_range_m`` (the information matrix ``Σ σ⁻² [[1, s], [s, s²]]``, i.e. the
joint covariance of reading note 8, so walls seen off to the side have the correlated, larger
covariance they have in real fits).  Odometry increments are the true ones perturbed on the
right by ``Exp(n)``, ``n ~ N(0, Q_u)`` with the motion model of :mod:`slam.ekf.motion` — the
estimators' model is then exactly right, which is what a consistency study needs.

The full simulator with ray casting and extraction is :mod:`slam.sim`.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from linefit.line import Line, normal_form
from slam.ekf.motion import odometry_covariance
from slam.errors import ConfigError
from slam.geometry import pose_between, pose_compose, pose_exp, predict_line_measurement
from slam.lines.lineset import LineSet
from slam.models.motion import MotionNoiseConfig
from slam.types import Scan

if TYPE_CHECKING:
    from slam.config import RunConfig

__all__ = [
    "LineRun",
    "LineSimConfig",
    "LineWorld",
    "corridor_loop_world",
    "grid_route",
    "grid_world",
    "lineset_to_lines",
    "loop_trajectory",
    "matched_run_config",
    "simulate_line_run",
    "visible_walls",
    "waypoint_trajectory",
    "world_and_trajectory",
]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class LineWorld:
    """Walls as world segments.

    Attributes
    ----------
    walls : ndarray, shape (W, 2, 2)
        End points ``[[x1, y1], [x2, y2]]`` of each wall (m).
    name : str
    """

    walls: FloatArray
    name: str = "world"

    @property
    def lines_r_alpha(self) -> FloatArray:
        """The walls' infinite lines in normal form, shape (W, 2)."""
        p, q = self.walls[:, 0], self.walls[:, 1]
        d = q - p
        n = np.stack([d[:, 1], -d[:, 0]], -1) / np.linalg.norm(d, axis=1)[:, None]
        r = np.sum(n * p, axis=1)
        alpha = np.arctan2(n[:, 1], n[:, 0])
        r_n, a_n, _ = normal_form(r, alpha)
        return np.stack([r_n, a_n], -1)


def _rect(x0: float, y0: float, x1: float, y1: float) -> list[list[list[float]]]:
    return [
        [[x0, y0], [x1, y0]],
        [[x1, y0], [x1, y1]],
        [[x1, y1], [x0, y1]],
        [[x0, y1], [x0, y0]],
    ]


def corridor_loop_world(
    length_m: float = 20.0, width_m: float = 10.0, corridor_m: float = 2.0
) -> LineWorld:
    """A rectangular corridor loop with a few short side walls (door frames, cabinets).

    The centre line of the corridor is the rectangle ``[0, length] × [0, width]``.
    """
    h = corridor_m / 2.0
    walls = _rect(-h, -h, length_m + h, width_m + h) + _rect(h, h, length_m - h, width_m - h)
    # short walls sticking out of the outer wall: they fix the position along the corridor
    for x in np.linspace(0.25 * length_m, 0.75 * length_m, 3):
        walls.append([[x, -h], [x, -h + 0.4]])
        walls.append([[x + 1.0, width_m + h], [x + 1.0, width_m + h - 0.4]])
    for y in (0.5 * width_m,):
        walls.append([[-h, y], [-h + 0.4, y]])
        walls.append([[length_m + h, y + 1.0], [length_m + h - 0.4, y + 1.0]])
    return LineWorld(np.asarray(walls, dtype=float), name="corridor_loop")


def waypoint_trajectory(waypoints: FloatArray, step_m: float = 0.25) -> FloatArray:
    """Laser poses driving straight between waypoints, turning on the spot at each one.

    Turns are taken in steps of at most 30°.  Returns shape (N, 3), starting at the first
    waypoint heading to the second.
    """
    wp = np.asarray(waypoints, dtype=float).reshape(-1, 2)
    poses: list[tuple[float, float, float]] = []
    heading = math.atan2(wp[1, 1] - wp[0, 1], wp[1, 0] - wp[0, 0])
    for a, b in itertools.pairwise(wp):
        new_heading = math.atan2(b[1] - a[1], b[0] - a[0])
        turn = math.remainder(new_heading - heading, 2 * math.pi)
        n_turn = math.ceil(abs(turn) / (math.pi / 6.0) - 1e-9)
        for k in range(1, n_turn):
            poses.append((a[0], a[1], heading + turn * k / n_turn))
        heading = new_heading
        n = max(round(math.hypot(*(b - a)) / step_m), 1)
        for i in range(n):
            f = i / n
            poses.append((a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]), heading))
    poses.append((wp[-1, 0], wp[-1, 1], heading))
    out = np.asarray(poses, dtype=float)
    out[:, 2] = np.pi - np.mod(np.pi - out[:, 2], 2 * np.pi)
    return out


def loop_trajectory(
    length_m: float = 20.0, width_m: float = 10.0, step_m: float = 0.25, loops: float = 1.0
) -> FloatArray:
    """Laser poses driving counter-clockwise around the rectangle ``[0, L] × [0, W]``.

    ``loops`` may be fractional (in quarter loops).  Returns shape (N, 3), starting at the
    origin heading along +x.
    """
    corners = np.array([[0.0, 0.0], [length_m, 0.0], [length_m, width_m], [0.0, width_m]])
    n_sides = math.ceil(4 * loops)
    wp = np.array([corners[i % 4] for i in range(n_sides + 1)])
    return waypoint_trajectory(wp, step_m)


def grid_world(
    nx: int = 2, ny: int = 2, block_m: tuple[float, float] = (8.0, 4.0), corridor_m: float = 2.0
) -> LineWorld:
    """Corridors around ``nx × ny`` rectangular blocks (an office floor).

    Corridor centre lines run along ``x = i·(bx + c)`` and ``y = j·(by + c)``; blocks fill the
    rest; an outer wall closes the floor.  Short stubs on the outer wall mark positions along
    the long corridors.
    """
    bx, by = block_m
    c = corridor_m
    h = c / 2.0
    X, Y = nx * (bx + c), ny * (by + c)
    walls = _rect(-h, -h, X + h, Y + h)
    for i in range(nx):
        for j in range(ny):
            x0, y0 = i * (bx + c) + h, j * (by + c) + h
            walls += _rect(x0, y0, x0 + bx, y0 + by)
    for x in np.arange(0.5 * (bx + c), X, bx + c):
        walls.append([[x - 1.0, -h], [x - 1.0, -h + 0.4]])
        walls.append([[x + 1.0, Y + h], [x + 1.0, Y + h - 0.4]])
    return LineWorld(np.asarray(walls, dtype=float), name=f"grid{nx}x{ny}")


def grid_route(
    nx: int = 2, ny: int = 2, block_m: tuple[float, float] = (8.0, 4.0), corridor_m: float = 2.0
) -> FloatArray:
    """Waypoints visiting every corridor of :func:`grid_world` and returning to the start."""
    sx, sy = block_m[0] + corridor_m, block_m[1] + corridor_m
    nodes: list[tuple[int, int]] = [(0, 0), (nx, 0), (nx, ny), (0, ny), (0, 0)]
    for i in range(1, nx):  # vertical corridors, up and down alternately
        nodes += [(i, 0), (i, ny)] if i % 2 else [(i, ny), (i, 0)]
    last = nodes[-1]
    for j in range(1, ny):  # horizontal corridors, end to end
        nodes += [(last[0], j), (nx, j), (0, j)]
        last = nodes[-1]
    nodes += [(last[0], 0), (0, 0)]
    pts = [(i * sx, j * sy) for i, j in nodes]
    dedup = [pts[0]] + [p for q, p in itertools.pairwise(pts) if p != q]
    return np.asarray(dedup, dtype=float)


SIM_ODOMETRY = MotionNoiseConfig(
    sigma_xy_per_m=0.02,
    sigma_xy_per_rad=0.0,
    sigma_theta_per_m=0.005,
    sigma_theta_per_rad=0.02,
    sigma_xy_min_m=1e-4,
    sigma_theta_min_rad=1e-4,
)
"""The line simulator's default odometry noise (the EKF's earlier default model)."""


@dataclass(frozen=True)
class LineSimConfig:
    """Noise and visibility of :func:`simulate_line_run`.

    Attributes
    ----------
    sigma_range_m : float
        Range noise of the notional points behind each fit (m).
    point_spacing_m : float
        Spacing of those points along the wall (m).
    max_range_m : float
        Walls are seen up to this distance (m).
    min_visible_length_m : float
        Shorter visible pieces give no line.
    samples_per_wall : int
        Samples along each wall for the occlusion test.
    odometry : MotionNoiseConfig
        Noise of the odometry increments (also what the estimators are told in the
        experiments: ``RunConfig.ekf.odometry`` and ``RunConfig.slam.motion``).  Default: 0.02
        m/√m, 0.02 rad/√rad, 0.005 rad/√m, floors 0.1 mm / 0.1 mrad (no translation error from
        turning).
    """

    sigma_range_m: float = 0.01
    point_spacing_m: float = 0.05
    max_range_m: float = 8.0
    min_visible_length_m: float = 0.3
    samples_per_wall: int = 40
    odometry: MotionNoiseConfig = field(default_factory=lambda: SIM_ODOMETRY)

    def __post_init__(self) -> None:
        for name in ("sigma_range_m", "point_spacing_m", "max_range_m"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0.0):
                raise ConfigError(f"linesim.{name} must be > 0, got {v!r}")
        if self.samples_per_wall < 2:
            raise ConfigError("linesim.samples_per_wall must be >= 2")


@dataclass(frozen=True, eq=False)
class LineRun:
    """One simulated run.

    Attributes
    ----------
    scans : list of Scan
        Scans with noisy odometry (``pose_odom_laser``) and no ranges.
    lines : list of LineSet
        Measured lines per scan (laser frame); ``ids`` are the wall indices (ground truth).
    poses_true : ndarray, shape (N, 3)
        True laser poses.
    world : LineWorld
    """

    scans: list[Scan]
    lines: list[LineSet]
    poses_true: FloatArray
    world: LineWorld


def _segments_intersect(
    p: FloatArray, q: FloatArray, a: FloatArray, b: FloatArray
) -> NDArray[np.bool_]:
    """Whether segments ``p→q`` (…, 2) properly cross ``a→b`` (…, 2), broadcasting."""

    def cross(u: FloatArray, v: FloatArray) -> FloatArray:
        return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]

    r, s = q - p, b - a
    den = cross(r, s)
    ok = np.abs(den) > 1e-12
    den = np.where(ok, den, 1.0)
    t = cross(a - p, s) / den
    u = cross(a - p, r) / den
    return np.asarray(ok & (t > 1e-9) & (t < 1.0 - 1e-6) & (u >= 0.0) & (u <= 1.0))


def visible_walls(
    world: LineWorld, pose_world_laser: FloatArray, config: LineSimConfig
) -> tuple[NDArray[np.intp], FloatArray]:
    """Walls seen from a pose and the world end points of their visible parts.

    Returns
    -------
    ids : ndarray of int, shape (V,)
    ends_world : ndarray, shape (V, 2, 2)
    """
    walls = world.walls
    W, n = walls.shape[0], config.samples_per_wall
    f = np.linspace(0.0, 1.0, n)
    start, end = walls[:, None, 0, :], walls[:, None, 1, :]
    samples = start + f[None, :, None] * (end - start)
    origin = np.asarray(pose_world_laser[:2], dtype=float)
    in_range = np.linalg.norm(samples - origin, axis=-1) <= config.max_range_m  # (W, n)
    # occlusion: ray origin→sample crosses another wall
    hits = _segments_intersect(
        origin[None, None, None, :],
        samples[:, :, None, :],
        walls[None, None, :, 0, :],
        walls[None, None, :, 1, :],
    )  # (W, n, W)
    own = np.eye(W, dtype=bool)[:, None, :]
    seen = in_range & ~np.any(hits & ~own, axis=-1)
    ids, ends = [], []
    for w in range(W):
        idx = np.flatnonzero(seen[w])
        if idx.size < 2:
            continue
        a, b = samples[w, idx[0]], samples[w, idx[-1]]
        if np.linalg.norm(b - a) < config.min_visible_length_m:
            continue
        ids.append(w)
        ends.append([a, b])
    return np.asarray(ids, dtype=np.intp), np.asarray(ends, dtype=float).reshape(-1, 2, 2)


def _fit_covariance(
    s_ends: FloatArray, sigma_m: float, spacing_m: float
) -> tuple[FloatArray, FloatArray]:
    """Covariance of ``(r, α)`` of a WLS fit to points spread over ``[s1, s2]``; (V, 2, 2)."""
    lo, hi = s_ends.min(axis=1), s_ends.max(axis=1)
    n = np.maximum(np.floor((hi - lo) / spacing_m) + 1.0, 2.0)
    mean = 0.5 * (lo + hi)
    # Σ s and Σ s² of n equally spaced points on [lo, hi]
    var_s = (hi - lo) ** 2 * (n + 1.0) / (12.0 * (n - 1.0))
    info = np.empty((lo.shape[0], 2, 2))
    info[:, 0, 0] = n
    info[:, 0, 1] = info[:, 1, 0] = -n * mean  # residual r − p·n(α): ∂/∂α = −s
    info[:, 1, 1] = n * (var_s + mean**2)
    return np.asarray(np.linalg.inv(info / sigma_m**2), dtype=float), n


def simulate_line_run(
    world: LineWorld,
    poses_true: FloatArray,
    config: LineSimConfig | None = None,
    seed: int | np.random.Generator = 0,
    start_time: float = 0.0,
    dt_s: float = 0.1,
) -> LineRun:
    """Noisy odometry and noisy lines along a true trajectory.

    Parameters
    ----------
    world : LineWorld
    poses_true : ndarray, shape (N, 3)
        True laser poses.
    config : LineSimConfig, optional
    seed : int or numpy.random.Generator
    start_time, dt_s : float
        Time stamps of the scans.

    Returns
    -------
    LineRun
        The odometry starts at the true first pose.
    """
    cfg = config or LineSimConfig()
    rng = np.random.default_rng(seed)
    poses_true = np.asarray(poses_true, dtype=float).reshape(-1, 3)
    N = poses_true.shape[0]
    inc_true = pose_between(poses_true[:-1], poses_true[1:])
    Q = odometry_covariance(inc_true, cfg.odometry)
    noise = np.einsum("kij,kj->ki", np.linalg.cholesky(Q), rng.standard_normal((N - 1, 3)))
    inc_meas = pose_compose(inc_true, pose_exp(noise))
    odom = np.empty((N, 3))
    odom[0] = poses_true[0]
    for k in range(1, N):
        odom[k] = pose_compose(odom[k - 1], inc_meas[k - 1])
    lines_world = world.lines_r_alpha
    scans: list[Scan] = []
    line_sets: list[LineSet] = []
    for k in range(N):
        pose = poses_true[k]
        ids, ends_w = visible_walls(world, pose, cfg)
        z_true, _, _ = predict_line_measurement(lines_world[ids], pose[None, :])
        r, a, _ = normal_form(z_true[:, 0], z_true[:, 1])
        # end points in the laser frame
        c, s = math.cos(pose[2]), math.sin(pose[2])
        rot_t = np.array([[c, s], [-s, c]])
        ends_l = (ends_w - pose[:2]) @ rot_t.T
        s_ends = -ends_l[..., 0] * np.sin(a)[:, None] + ends_l[..., 1] * np.cos(a)[:, None]
        cov, _ = _fit_covariance(s_ends, cfg.sigma_range_m, cfg.point_spacing_m)
        eps = np.einsum("kij,kj->ki", np.linalg.cholesky(cov), rng.standard_normal((len(ids), 2)))
        z = np.stack([r, a], -1) + eps
        r_n, a_n, flipped = normal_form(z[:, 0], z[:, 1])
        cov = cov.copy()
        cov[flipped, 0, 1] *= -1.0
        cov[flipped, 1, 0] *= -1.0
        line_sets.append(LineSet(np.stack([r_n, a_n], -1), cov, ends_l, ids.astype(np.int64)))
        scans.append(
            Scan(
                index=k,
                timestamp=start_time + k * dt_s,
                ranges=np.zeros(0),
                bearings=np.zeros(0),
                pose_odom_laser=odom[k].copy(),
                source=f"linesim:{world.name}",
            )
        )
    return LineRun(scans, line_sets, poses_true, world)


LINE_WORLD_NAMES = ("corridor_loop", "gridNxM")
"""Worlds built here; the ray-cast simulator's (:data:`slam.sim.worlds.WORLD_NAMES`) work too."""


def sim_world_names() -> tuple[str, ...]:
    """Every simulated world name, the same for ``lineslam simulate`` and ``compare sim:``."""
    from slam.sim.worlds import WORLD_NAMES

    return (*LINE_WORLD_NAMES, *WORLD_NAMES)


def _line_world_waypoints(name: str) -> tuple[LineWorld, FloatArray] | None:
    """The world and route waypoints of a name built here (``None`` if not one)."""
    if name == "corridor_loop":
        corners = np.array([[0.0, 0.0], [20.0, 0.0], [20.0, 10.0], [0.0, 10.0], [0.0, 0.0]])
        return corridor_loop_world(), corners
    if name.startswith("grid"):
        try:
            nx, ny = (int(v) for v in name[4:].split("x"))
        except ValueError as exc:
            raise ConfigError(f"world {name!r}: expected 'gridNxM'") from exc
        return grid_world(nx, ny), grid_route(nx, ny)
    return None


def world_and_trajectory(name: str, loops: float = 1.0) -> tuple[LineWorld, FloatArray]:
    """A named simulated world and its trajectory.

    ``"corridor_loop"``, ``"gridNxM"``, or a world of the ray-cast simulator
    (:data:`slam.sim.worlds.WORLD_NAMES`: ``hallway``, ``lab``, ``loop``), whose walls become
    the line world and whose waypoints the route.  ``loops`` repeats the route (corridor
    loop: around the rectangle, in quarter loops; others: the whole route, rounded).
    """
    if name == "corridor_loop":
        return corridor_loop_world(), loop_trajectory(loops=loops)
    built = _line_world_waypoints(name)
    if built is not None:
        world, route = built
    else:
        from slam.sim.worlds import WORLD_NAMES, get_world

        if name not in WORLD_NAMES:
            raise ConfigError(f"unknown simulated world {name!r} ({', '.join(sim_world_names())})")
        ray_world = get_world(name)
        if ray_world.waypoints is None:  # pragma: no cover - every named world has a route
            raise ConfigError(f"world {name!r} has no route")
        world = LineWorld(np.asarray(ray_world.segments, dtype=float), name)
        route = np.asarray(ray_world.waypoints, dtype=float)
    reps = max(round(loops), 1)
    wp = np.vstack([route] + [route[1:]] * (reps - 1))
    return world, waypoint_trajectory(wp)


def ray_world(name: str) -> Any:
    """A world built here as a :class:`slam.sim.world.World` for the ray-cast simulator.

    ``None`` for a name that is not built here (the simulator knows those itself).
    """
    from slam.sim.world import World

    built = _line_world_waypoints(name)
    if built is None:
        return None
    world, route = built
    if name.startswith("grid"):
        # the ray-cast simulator's paths do not turn back on themselves: drive the horizontal
        # corridors as a snake, then back along the last side and the first corridor
        nx, ny = (int(v) for v in name[4:].split("x"))
        sx, sy = 8.0 + 2.0, 4.0 + 2.0
        nodes: list[tuple[float, float]] = [(0.0, 0.0)]
        for j in range(ny + 1):
            ends = [(0.0, j * sy), (nx * sx, j * sy)]
            nodes += ends if j % 2 == 0 else ends[::-1]
        last_x = nodes[-1][0]
        nodes += [(last_x, 0.0), (nx * sx - last_x, 0.0)]
        route = np.array(nodes[1:], dtype=float)
    n = world.walls.shape[0]
    return World(
        segments=world.walls,
        ids=np.arange(n),
        labels=("wall",) * n,
        name=name,
        waypoints=route,
        description=f"{name} (the line simulator's world, slam.experiments.linesim)",
    )


def lineset_to_lines(lines: LineSet, point_spacing_m: float = 0.05) -> list[Line]:
    """The simulated lines of one scan as :class:`linefit.Line` objects (for the graph).

    The graph back-end takes the per-scan output of ``linefit`` (segment extents along the
    line, their variances, the number of supporting points); a simulated line gets its visible
    part projected on the measured line as its one segment, the notional points behind its fit
    (``length / point_spacing_m + 1``) as ``n_points``, and its ``(r, α)`` covariance; the
    ``s`` entries (not used for estimation) get a variance of ``point_spacing_m²``.
    """
    out: list[Line] = []
    for k in range(len(lines)):
        r, a = (float(v) for v in lines.r_alpha[k])
        r_n, a_n, flipped = normal_form(np.array([r]), np.array([a]))
        r, a = float(r_n[0]), float(a_n[0])
        cov2 = np.array(lines.cov[k], dtype=float)
        if bool(flipped[0]):
            cov2[0, 1] *= -1.0
            cov2[1, 0] *= -1.0
        ends = lines.endpoints[k]
        s_ends = np.sort(-ends[:, 0] * math.sin(a) + ends[:, 1] * math.cos(a))
        cov = np.zeros((3, 3))
        cov[:2, :2] = cov2
        cov[2, 2] = point_spacing_m**2
        n = int(np.floor((s_ends[1] - s_ends[0]) / point_spacing_m)) + 1
        out.append(
            Line(
                r=r,
                alpha=a,
                s=float(np.mean(s_ends)),
                cov=cov,
                segments_s=s_ends.reshape(1, 2),
                segments_var=np.full((1, 2), point_spacing_m**2),
                n_points=max(n, 2),
            )
        )
    return out


def matched_run_config(run_config: RunConfig, sim: LineSimConfig) -> RunConfig:
    """The run configuration with the estimators told the line simulator's true noise models.

    Both estimators get the simulator's odometry noise (``ekf.odometry``, ``slam.motion``) and
    no model-error floor on the lines (the simulated fits' covariances are exact), and the
    graph no pass error (``slam.line_pass_error = "off"``: the simulator draws every
    observation's error on its own), so that a consistency study measures the estimators and
    not a mismatched model.  Everything else (gates, keyframes, association, ...) stays as
    configured.
    """
    ekf = replace(run_config.ekf, odometry=sim.odometry, line_sigma_extra=(0.0, 0.0))
    slam_cfg = replace(run_config.slam, motion=sim.odometry, line_pass_error="off")
    floors: dict[str, Any] = {
        name: 0.0
        for name in ("line_model_sigma_r_m", "line_model_sigma_alpha_rad")
        if hasattr(slam_cfg, name)
    }
    if floors:
        slam_cfg = replace(slam_cfg, **floors)
    return replace(run_config, ekf=ekf, slam=slam_cfg)
