"""A tiny 2D ray caster for tests: walls and boxes (segments), pillars (circles), noisy scans.

Noise models (see ``linefit.covariance``):

* ``"beam"``: the physical beam leaves at ``φ + ε_φ`` and hits the world there; the reading is
  that range plus ``ε_d``, reported at the nominal bearing ``φ``;
* ``"reading"``: the beam leaves at ``φ``, the reported bearing is ``φ + ε_φ``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from linefit.line import wrap_angle


@dataclass
class World:
    """Segments ``(k, 2, 2)`` (``[[x0, y0], [x1, y1]]``) and circles ``(c, 3)`` (x, y, radius)."""

    segments: np.ndarray
    circles: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))

    @property
    def n_segments(self) -> int:
        return int(self.segments.shape[0])


def box(cx: float, cy: float, w: float, h: float, theta: float) -> np.ndarray:
    """The four faces of a ``w × h`` rectangle centred at ``(cx, cy)`` rotated by ``theta``."""
    corners = np.array([[-w, -h], [w, -h], [w, h], [-w, h]]) * 0.5
    c, s = np.cos(theta), np.sin(theta)
    corners = corners @ np.array([[c, s], [-s, c]]) + [cx, cy]
    return np.stack([corners, np.roll(corners, -1, axis=0)], axis=1)


def room() -> World:
    """A 10 m × 8 m room with two boxes and a pillar (no two faces collinear)."""
    walls = box(0.0, 0.0, 10.0, 8.0, 0.0)
    boxes = np.concatenate([box(2.2, 1.6, 1.2, 0.7, 0.35), box(-2.6, -1.9, 0.9, 0.9, -0.6)])
    return World(np.concatenate([walls, boxes]), np.array([[1.6, -2.2, 0.25]]))


def cast(
    world: World, pose: np.ndarray, bearings: np.ndarray, max_range: float = 80.0
) -> tuple[np.ndarray, np.ndarray]:
    """Exact ranges along ``bearings`` (sensor frame) from ``pose = (x, y, θ)``.

    Returns ranges (``max_range`` where nothing is hit) and the id of the primitive hit
    (segments ``0..k-1``, circles ``k..``, ``-1`` for no hit).
    """
    ang = pose[2] + bearings
    dx, dy = np.cos(ang)[:, None], np.sin(ang)[:, None]
    ox, oy = pose[0], pose[1]
    best = np.full(bearings.shape[0], np.inf)
    hit = np.full(bearings.shape[0], -1)
    if world.n_segments:
        p0 = world.segments[:, 0]
        e = world.segments[:, 1] - p0
        # solve o + t·dir = p0 + u·e
        den = dx * e[:, 1] - dy * e[:, 0]
        wx, wy = p0[:, 0] - ox, p0[:, 1] - oy
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (wx * e[:, 1] - wy * e[:, 0]) / den
            u = (wx * dy - wy * dx) / den
        ok = (np.abs(den) > 1e-12) & (t > 1e-9) & (u >= 0.0) & (u <= 1.0)
        t = np.where(ok, t, np.inf)
        k = np.argmin(t, axis=1)
        tk = t[np.arange(t.shape[0]), k]
        better = tk < best
        best = np.where(better, tk, best)
        hit = np.where(better, k, hit)
    for c, (cx, cy, rad) in enumerate(world.circles):
        fx, fy = ox - cx, oy - cy
        b = fx * dx[:, 0] + fy * dy[:, 0]
        disc = b * b - (fx * fx + fy * fy - rad * rad)
        with np.errstate(invalid="ignore"):
            t = -b - np.sqrt(disc)
        ok = (disc >= 0) & (t > 1e-9)
        better = ok & (t < best)
        best = np.where(better, t, best)
        hit = np.where(better, world.n_segments + c, hit)
    best = np.where(np.isfinite(best) & (best < max_range), best, max_range)
    hit = np.where(best < max_range, hit, -1)
    return best, hit


def noisy_scan(
    world: World,
    pose: np.ndarray,
    bearings: np.ndarray,
    rng: np.random.Generator,
    sigma_d: float = 0.005,
    sigma_phi: float = 1e-4,
    model: str = "beam",
    max_range: float = 80.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A noisy scan: (ranges, reported bearings, hit ids)."""
    eps_phi = rng.normal(0.0, sigma_phi, bearings.shape)
    if model == "beam":
        ranges, hit = cast(world, pose, bearings + eps_phi, max_range)
        reported = bearings.copy()
    else:
        ranges, hit = cast(world, pose, bearings, max_range)
        reported = bearings + eps_phi
    ranges = np.where(hit >= 0, ranges + rng.normal(0.0, sigma_d, bearings.shape), max_range)
    return ranges, reported, hit


def segment_line_in_sensor(world: World, k: int, pose: np.ndarray) -> tuple[float, float]:
    """Normal form ``(r, α)`` of segment ``k``'s infinite line in the sensor frame at ``pose``."""
    p0, p1 = world.segments[k]
    c, s = np.cos(pose[2]), np.sin(pose[2])
    rot = np.array([[c, s], [-s, c]])
    q0 = rot @ (p0 - pose[:2])
    q1 = rot @ (p1 - pose[:2])
    t = q1 - q0
    n = np.array([-t[1], t[0]]) / np.hypot(*t)
    r = float(n @ q0)
    alpha = float(np.arctan2(n[1], n[0]))
    if r < 0:
        r, alpha = -r, float(wrap_angle(alpha + np.pi))
    return r, alpha


def wall_scan(
    r: float,
    alpha: float,
    s_values: np.ndarray,
    n_trials: int,
    rng: np.random.Generator,
    sigma_d: float = 0.005,
    sigma_phi: float = 1e-4,
    sigma_per_m: float = 0.0,
    model: str = "beam",
) -> dict[str, np.ndarray]:
    """Many noisy observations of one infinite wall, beams aimed at the points ``s_values``.

    Returns arrays of shape ``(n_trials, n)``: ``ranges``, ``bearings``; and the truth:
    ``s_true`` (``(n,)``, along-wall position of each beam's reference point: the point on the
    nominal ray for ``"beam"``, the physical hit point for ``"reading"``), ``ranges_true``,
    ``bearings_true``.
    """
    n_vec = np.array([np.cos(alpha), np.sin(alpha)])
    t_vec = np.array([-np.sin(alpha), np.cos(alpha)])
    pts = r * n_vec + s_values[:, None] * t_vec
    d_true = np.hypot(pts[:, 0], pts[:, 1])
    phi_true = np.arctan2(pts[:, 1], pts[:, 0])
    shape = (n_trials, s_values.shape[0])
    eps_phi = rng.normal(0.0, sigma_phi, shape)
    eps_d = rng.normal(0.0, 1.0, shape)
    if model == "beam":
        phys = phi_true + eps_phi
        d = r / np.cos(phys - alpha)
        ranges = d + eps_d * (sigma_d + sigma_per_m * d)
        bearings = np.broadcast_to(phi_true, shape).copy()
    else:
        ranges = d_true + eps_d * (sigma_d + sigma_per_m * d_true)
        bearings = phi_true + eps_phi
    return {
        "ranges": ranges,
        "bearings": bearings,
        "s_true": s_values.astype(float),
        "ranges_true": d_true,
        "bearings_true": phi_true,
    }
