"""Exact ray casting against line segments, vectorised over rays × segments.

A ray ``o + t·d`` (``t > 0``, ``|d| = 1``) meets the segment ``a + u·(b − a)`` (``0 ≤ u ≤ 1``)
where

``t = ((a − o) × e) / (d × e)``,  ``u = ((a − o) × d) / (d × e)``,  ``e = b − a``,

with ``×`` the planar cross product.  The range is the smallest ``t`` over all segments; the
hit id is that segment's id.  Conventions at the edges:

* A ray parallel to a segment (``d × e = 0``, including a ray running exactly along it) does
  not hit it: walls have no thickness.  It hits whatever stands at the segment's end.
* Segments that share an end point (corners) are closed at both ends with a relative tolerance
  of 1e-12 on ``u``, so a ray through a corner never slips between the two walls.
* Intersections at ``t ≤ 1e-9`` m (the ray starting on a wall) are ignored.
* Where nothing is hit, or the hit is at or beyond ``max_range_m``, the range is
  ``max_range_m`` and the id ``-1``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slam.errors import InputError
from slam.sim.world import World

__all__ = ["cast_rays", "cast_scan"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

_U_TOL = 1e-12
_T_MIN_M = 1e-9
#: Largest number of ray × segment pairs evaluated at once (memory ~ 8 arrays of this size).
_CHUNK_PAIRS = 1 << 20


def cast_rays(
    origins_xy: ArrayLike,
    angles_rad: ArrayLike,
    world: World,
    max_range_m: float = np.inf,
) -> tuple[FloatArray, IntArray]:
    """Cast rays from ``origins_xy`` in world directions ``angles_rad``.

    Parameters
    ----------
    origins_xy : array_like, shape (n, 2) or (2,)
        Ray origins in the world frame (m); broadcast against ``angles_rad``.
    angles_rad : array_like, shape (n,)
        Ray directions in the world frame (rad).
    world : World
        The segments to hit.
    max_range_m : float
        Hits at or beyond this distance count as no hit.

    Returns
    -------
    ranges_m : ndarray, shape (n,)
        Distance to the first segment hit, ``max_range_m`` where none.
    hit_ids : ndarray of int, shape (n,)
        Id of the segment hit, ``-1`` where none.
    """
    angles = np.asarray(angles_rad, dtype=np.float64).reshape(-1)
    origins = np.broadcast_to(np.asarray(origins_xy, dtype=np.float64), (angles.shape[0], 2))
    if not (np.isfinite(angles).all() and np.isfinite(origins).all()):
        raise InputError("ray origins and angles must be finite")
    if not max_range_m > 0.0:
        raise InputError(f"max_range_m must be > 0, got {max_range_m!r}")
    n = angles.shape[0]
    ranges = np.full(n, max_range_m, dtype=np.float64)
    hit_ids = np.full(n, -1, dtype=np.int64)
    a = world.segments[:, 0]  # (S, 2)
    e = world.segments[:, 1] - a  # (S, 2)
    n_seg = a.shape[0]
    chunk = max(1, _CHUNK_PAIRS // n_seg)
    for start in range(0, n, chunk):
        stop = min(n, start + chunk)
        t, k = _first_hits(origins[start:stop], angles[start:stop], a, e)
        hit = t < max_range_m
        ranges[start:stop] = np.where(hit, t, max_range_m)
        hit_ids[start:stop] = np.where(hit, world.ids[k], -1)
    return ranges, hit_ids


def _first_hits(
    origins: FloatArray, angles: FloatArray, a: FloatArray, e: FloatArray
) -> tuple[FloatArray, IntArray]:
    """Smallest positive ``t`` over segments per ray (``inf`` if none) and its segment index."""
    dx, dy = np.cos(angles)[:, None], np.sin(angles)[:, None]  # (R, 1)
    wx = a[None, :, 0] - origins[:, 0:1]  # (R, S)
    wy = a[None, :, 1] - origins[:, 1:2]
    ex, ey = e[None, :, 0], e[None, :, 1]  # (1, S)
    den = dx * ey - dy * ex  # d × e
    parallel = den == 0.0
    den_safe = np.where(parallel, 1.0, den)
    t = (wx * ey - wy * ex) / den_safe  # ((a − o) × e) / (d × e)
    u = (wx * dy - wy * dx) / den_safe  # ((a − o) × d) / (d × e)
    valid = ~parallel & (t > _T_MIN_M) & (u >= -_U_TOL) & (u <= 1.0 + _U_TOL)
    t = np.where(valid, t, np.inf)
    k = np.argmin(t, axis=1)
    return t[np.arange(t.shape[0]), k], k


def cast_scan(
    pose_world_laser: ArrayLike,
    bearings_rad: ArrayLike,
    world: World,
    max_range_m: float = np.inf,
) -> tuple[FloatArray, IntArray]:
    """Noise-free scan: ranges and hit ids of beams at ``bearings_rad`` (laser frame).

    Parameters
    ----------
    pose_world_laser : array_like, shape (3,)
        ``(x, y, θ)`` of the laser in the world.
    bearings_rad : array_like, shape (n,)
        Beam angles in the laser frame.
    world, max_range_m
        As in :func:`cast_rays`.
    """
    pose = np.asarray(pose_world_laser, dtype=np.float64)
    if pose.shape != (3,):
        raise InputError(f"pose_world_laser must have shape (3,), got {pose.shape}")
    bearings = np.asarray(bearings_rad, dtype=np.float64)
    return cast_rays(pose[:2], pose[2] + bearings, world, max_range_m)
