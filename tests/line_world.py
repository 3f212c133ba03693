"""A line-level simulator for the graph tests: walls → noisy lines with known covariances.

Walls are segments with a free-space side; a wall is seen from a pose when the laser is on its
free side and part of it lies within range (no occlusion: worlds are laid out so that it does
not matter).  Each seen wall becomes a :class:`linefit.Line` in the laser frame whose ``(r, α)``
error is drawn from the covariance of a line fitted around the visible piece's mid-point:
``σ_c`` across the line at the mid-point and ``σ_α`` in angle, i.e.
``R = [[σ_c² + s̄² σ_α², −s̄ σ_α²], [−s̄ σ_α², σ_α²]]`` (``s̄`` the mid-point's tangent coordinate).
Odometry is the true motion with right-perturbation noise of a
:class:`~slam.models.motion.MotionNoiseConfig` covariance, so everything is consistent with the
models the estimator assumes.  Seeded and vectorised per scan.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from linefit.line import Line, normal_form
from slam.geometry import pose_between, pose_compose, pose_exp, pose_inverse
from slam.models.motion import MotionNoiseConfig, OdometryCalibration
from slam.types import Scan


@dataclass(frozen=True)
class World:
    """Walls ``(W, 2, 2)`` and the unit normal of each wall's free side ``(W, 2)``."""

    walls: np.ndarray
    free_normals: np.ndarray

    def wall_lines(self) -> np.ndarray:
        """World lines ``(r, α)`` of the walls, normal form."""
        p1, p2 = self.walls[:, 0], self.walls[:, 1]
        d = p2 - p1
        n = np.column_stack([d[:, 1], -d[:, 0]]) / np.linalg.norm(d, axis=1)[:, None]
        r = np.sum(n * p1, axis=1)
        r, a, _ = normal_form(r, np.arctan2(n[:, 1], n[:, 0]))
        return np.column_stack([r, a])


def box(x0: float, y0: float, x1: float, y1: float, inward: bool) -> tuple[list, list]:
    """The four walls of a rectangle, free side inside (``inward``) or outside."""
    c = [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
    walls, normals = [], []
    for k in range(4):
        p, q = np.array(c[k]), np.array(c[(k + 1) % 4])
        d = q - p
        n_left = np.array([-d[1], d[0]]) / np.linalg.norm(d)  # left of p→q (inside, ccw)
        walls.append([p, q])
        normals.append(n_left if inward else -n_left)
    return walls, normals


def split_walls(walls: list, normals: list, piece: float, door: float) -> tuple[list, list]:
    """Cut walls into pieces of about ``piece`` metres separated by ``door``-wide gaps."""
    out_w, out_n = [], []
    for (p, q), n in zip(walls, normals, strict=True):
        p, q = np.asarray(p, float), np.asarray(q, float)
        length = np.linalg.norm(q - p)
        k = max(1, round((length + door) / (piece + door)))
        seg = (length - (k - 1) * door) / k
        d = (q - p) / length
        for j in range(k):
            a = p + d * j * (seg + door)
            out_w.append([a, a + d * seg])
            out_n.append(n)
    return out_w, out_n


def corridor_loop(
    length: float = 16.0,
    width: float = 8.0,
    half_width: float = 1.0,
    piece: float | None = None,
    door: float = 1.0,
) -> World:
    """A rectangular corridor loop around a block; the centre line is the rectangle
    ``[0, length] × [0, width]``.  With ``piece``, walls are cut into pieces with doors between
    them, so that landmarks are local and returning to the start is a real loop closure."""
    w1, n1 = box(-half_width, -half_width, length + half_width, width + half_width, True)
    w2, n2 = box(half_width, half_width, length - half_width, width - half_width, False)
    walls, normals = w1 + w2, n1 + n2
    if piece is not None:
        walls, normals = split_walls(walls, normals, piece, door)
    return World(np.array(walls, dtype=float), np.array(normals, dtype=float))


def straight_corridor(length: float = 30.0, half_width: float = 1.0) -> World:
    """Two long parallel walls: position along the corridor is unobservable from lines."""
    walls = [
        [[-5.0, -half_width], [length, -half_width]],
        [[-5.0, half_width], [length, half_width]],
    ]
    return World(np.array(walls), np.array([[0.0, 1.0], [0.0, -1.0]]))


def loop_path(length: float, width: float, step: float, laps: float = 1.0) -> np.ndarray:
    """Laser poses along the rectangle ``[0, length] × [0, width]`` (ccw), ``step`` apart, turning
    on the spot at the corners."""
    poses = []
    corners = [(0.0, 0.0), (length, 0.0), (length, width), (0.0, width)]
    headings = [0.0, np.pi / 2, np.pi, -np.pi / 2]
    total_sides = round(4 * laps)
    for k in range(total_sides):
        c0 = np.array(corners[k % 4])
        c1 = np.array(corners[(k + 1) % 4])
        side = np.linalg.norm(c1 - c0)
        n = round(side / step)
        for j in range(n):
            p = c0 + (c1 - c0) * j / n
            poses.append([p[0], p[1], headings[k % 4]])
        # turn at the corner in a few steps
        h0, h1 = headings[k % 4], headings[(k + 1) % 4]
        for a in np.linspace(0.0, 1.0, 4)[1:-1]:
            d = np.arctan2(np.sin(h1 - h0), np.cos(h1 - h0))
            poses.append([c1[0], c1[1], h0 + a * d])
    poses.append([*corners[total_sides % 4], headings[total_sides % 4]])
    return np.array(poses)


def observe(
    world: World,
    pose: np.ndarray,
    rng: np.random.Generator,
    max_range: float = 6.0,
    sigma_c: float = 0.004,
    sigma_alpha: float = 0.002,
    min_length: float = 0.3,
) -> tuple[list[Line], np.ndarray]:
    """Noisy lines of the walls seen from ``pose`` and the indices of those walls."""
    p = pose[:2]
    lines, seen = [], []
    for w, (wall, n_free) in enumerate(zip(world.walls, world.free_normals, strict=True)):
        if np.dot(p - wall[0], n_free) <= 0.05:
            continue
        a, b = wall
        d = b - a
        # part of the wall within range: |a + t d − p|² ≤ R²
        A = d @ d
        B = 2 * d @ (a - p)
        C = (a - p) @ (a - p) - max_range**2
        disc = B * B - 4 * A * C
        if disc <= 0:
            continue
        t0 = max(0.0, (-B - np.sqrt(disc)) / (2 * A))
        t1 = min(1.0, (-B + np.sqrt(disc)) / (2 * A))
        if (t1 - t0) * np.sqrt(A) < min_length:
            continue
        ends_w = np.array([a + t0 * d, a + t1 * d])
        inv = pose_inverse(pose)
        ends_l = pose_compose(inv, np.column_stack([ends_w, np.zeros(2)]))[:, :2]
        dl = ends_l[1] - ends_l[0]
        nl = np.array([dl[1], -dl[0]]) / np.linalg.norm(dl)
        r_true = nl @ ends_l[0]
        r_true, a_true, _ = normal_form(r_true, np.arctan2(nl[1], nl[0]))
        r_true, a_true = float(r_true), float(a_true)
        t_hat = np.array([-np.sin(a_true), np.cos(a_true)])
        s_ends = np.sort(ends_l @ t_hat)
        s_mid = float(np.mean(s_ends))
        R = np.array(
            [
                [sigma_c**2 + s_mid**2 * sigma_alpha**2, -s_mid * sigma_alpha**2],
                [-s_mid * sigma_alpha**2, sigma_alpha**2],
            ]
        )
        e = np.linalg.cholesky(R) @ rng.standard_normal(2)
        r_m, a_m, _ = normal_form(r_true + e[0], a_true + e[1])
        cov = np.zeros((3, 3))
        cov[:2, :2] = R
        cov[2, 2] = 0.01
        length = s_ends[1] - s_ends[0]
        lines.append(
            Line(
                r=float(r_m),
                alpha=float(a_m),
                s=s_mid,
                cov=cov,
                segments_s=s_ends[None, :],
                segments_var=np.full((1, 2), 1e-4),
                n_points=max(5, int(length / 0.02)),
            )
        )
        seen.append(w)
    return lines, np.array(seen, dtype=int)


@dataclass(frozen=True)
class Run:
    """A simulated run: scans with odometry, their lines, and the truth."""

    scans: list[Scan]
    lines: list[list[Line]]
    poses_true: np.ndarray
    odometry: np.ndarray


def simulate_run(
    world: World,
    poses_true: np.ndarray,
    seed: int,
    motion: MotionNoiseConfig,
    max_range: float = 6.0,
    bias: OdometryCalibration | None = None,
) -> Run:
    """Scans along ``poses_true`` with noisy odometry (odometry frame = world at the start).

    ``bias``: the odometry misreads every step so that ``bias.apply`` of its step is the true
    one (then the random walk of ``motion`` is added); with a mounting, the odometry reports
    the motion of the point ``bias.mount_*`` behind the laser.
    """
    rng = np.random.default_rng(seed)
    rel = pose_between(poses_true[:-1], poses_true[1:])
    if bias is not None:
        mount = np.array([bias.mount_x_m, bias.mount_y_m, 0.0])
        # the laser's step M⁻¹·B·M undone: the odometry's point moves by B = M·step·M⁻¹
        raw = pose_compose(pose_compose(mount, rel), pose_inverse(mount))
        raw[:, :2] /= 1.0 + bias.scale
        d_raw = np.hypot(raw[:, 0], raw[:, 1])
        raw[:, 2] = (rel[:, 2] - bias.heading_drift_rad_per_m * d_raw) / (1.0 + bias.turn_gain)
        rel = raw
    cov = motion.covariance(rel)
    noise = np.einsum("eij,ej->ei", np.linalg.cholesky(cov), rng.standard_normal(rel.shape))
    rel_noisy = pose_compose(rel, pose_exp(noise))
    odo = np.zeros_like(poses_true)
    odo[0] = poses_true[0]
    for k in range(1, poses_true.shape[0]):
        odo[k] = pose_compose(odo[k - 1], rel_noisy[k - 1])
    scans, lines = [], []
    for k, p in enumerate(poses_true):
        ls, _ = observe(world, p, rng, max_range=max_range)
        lines.append(ls)
        scans.append(
            Scan(
                index=k,
                timestamp=1000.0 + 0.1 * k,
                ranges=np.zeros(0),
                bearings=np.zeros(0),
                pose_odom_laser=odo[k],
                source=f"sim:{k}",
            )
        )
    return Run(scans, lines, poses_true, odo)


def relations_error(poses: np.ndarray, truth: np.ndarray, gap: int) -> np.ndarray:
    """|translation error| of the relative poses ``(k, k + gap)`` against the truth."""
    est = pose_between(poses[:-gap], poses[gap:])
    ref = pose_between(truth[:-gap], truth[gap:])
    err = pose_between(ref, est)
    return np.hypot(err[:, 0], err[:, 1])
