"""Simulate a laser log: true poses → noisy scans, noisy odometry, relations.

Per scan ``k`` and beam ``i`` (bearing ``Φ_i`` in the laser frame), following the paper's
Section II: the true ray leaves the laser at the world angle ``θ_k + Φ_i + ε_φ`` and meets the
first wall at the true range ``D``; the log reports ``d = D + ε_d`` at the bearing ``Φ_i``.
Beams that hit nothing within ``max_range_m`` read ``max_range_m`` (no return) with hit id
``-1``.  A noisy reading is clipped at 0 and, if it reaches ``max_range_m``, also counts as no
return.

Randomness: ``numpy.random.SeedSequence(seed)`` is split into four independent streams
(bearing noise, range noise, odometry noise, relation choice), so changing e.g. the odometry
noise leaves the laser readings of the same seed unchanged.  Every beam draws its noise whether
it hits or not, so the streams do not depend on the geometry either.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from slam.errors import InputError
from slam.geometry import pose_compose
from slam.sim.config import SimConfig
from slam.sim.odometry import simulate_odometry
from slam.sim.raycast import cast_rays
from slam.sim.relations import relation_pairs
from slam.sim.trajectory import SimTrajectory, trajectory_from_waypoints
from slam.sim.world import World
from slam.types import Scan

__all__ = ["SimulatedLog", "simulate"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: Scans ray-cast per step (the progress callback is called after each).
SCANS_PER_CHUNK = 64


@dataclass(frozen=True, eq=False)
class SimulatedLog:
    """A simulated log and its ground truth.

    Attributes
    ----------
    world : World
        The world the scans were cast in.
    config : SimConfig
        The configuration used (with ``seed`` set to the seed actually used).
    timestamps : ndarray, shape (n,)
        Scan time stamps (s, µs resolution).
    poses_world_base : ndarray, shape (n, 3)
        True base poses.
    poses_odom_base : ndarray, shape (n, 3)
        Odometry base poses (noisy; the odometry frame is the world frame at scan 0).
    bearings_rad : ndarray, shape (m,)
        Reported beam angles in the laser frame.
    ranges_m : ndarray, shape (n, m)
        Noisy readings (``max_range_m`` = no return), full precision (the log rounds them).
    hit_ids : ndarray of int, shape (n, m)
        Id of the segment each beam hit, ``-1`` for no return.
    true_ranges_m : ndarray, shape (n, m)
        Noise-free range along each (bearing-perturbed) ray, ``max_range_m`` where none.
    relation_pairs : ndarray of int, shape (k, 2)
        Scan index pairs ``(i, j)``, ``i < j``, of the ground-truth relations.
    """

    world: World
    config: SimConfig
    timestamps: FloatArray
    poses_world_base: FloatArray
    poses_odom_base: FloatArray
    bearings_rad: FloatArray
    ranges_m: FloatArray
    hit_ids: IntArray
    true_ranges_m: FloatArray
    relation_pairs: IntArray

    @property
    def n_scans(self) -> int:
        """Number of scans."""
        return int(self.timestamps.shape[0])

    @property
    def n_beams(self) -> int:
        """Beams per scan."""
        return int(self.bearings_rad.shape[0])

    @property
    def max_range_m(self) -> float:
        """Reading of a beam with no return (m)."""
        return self.config.laser.max_range_m

    @property
    def pose_base_laser(self) -> FloatArray:
        """Mounting of the laser on the base ``(x, y, θ)``."""
        return np.asarray(self.config.laser.pose_base_laser, dtype=np.float64)

    @property
    def poses_world_laser(self) -> FloatArray:
        """True laser poses ``(n, 3)`` (the ground truth written to ``ground_truth.tum``)."""
        return pose_compose(self.poses_world_base, self.pose_base_laser)

    @property
    def poses_odom_laser(self) -> FloatArray:
        """Odometry laser poses ``(n, 3)`` (CARMEN ``FLASER x y theta``)."""
        return pose_compose(self.poses_odom_base, self.pose_base_laser)

    def scans(self) -> Iterator[Scan]:
        """The scans as :class:`~slam.types.Scan` objects, in order."""
        odom_laser = self.poses_odom_laser
        for k in range(self.n_scans):
            yield Scan(
                index=k,
                timestamp=float(self.timestamps[k]),
                ranges=self.ranges_m[k],
                bearings=self.bearings_rad,
                max_range_m=self.max_range_m,
                pose_odom_base=self.poses_odom_base[k],
                pose_odom_laser=odom_laser[k],
                source=f"sim:{self.world.name}:{k}",
            )


def simulate(
    world: World,
    trajectory: SimTrajectory | None = None,
    config: SimConfig | None = None,
    seed: int | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> SimulatedLog:
    """Simulate the scans, odometry and relations of a robot driving through ``world``.

    Parameters
    ----------
    world : World
        Wall segments.
    trajectory : SimTrajectory, optional
        True base poses and time stamps; default: the world's waypoints driven as
        ``config.trajectory`` says.
    config : SimConfig, optional
        Laser, noise, odometry, trajectory and relations settings (default :class:`SimConfig`).
    seed : int, optional
        Overrides ``config.seed``.
    progress : callable, optional
        Called as ``progress(scans_done, scans_total)`` after each chunk of scans.

    Returns
    -------
    SimulatedLog
    """
    config = config or SimConfig()
    if seed is not None:
        if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
            raise InputError(f"seed must be an integer >= 0, got {seed!r}")
        config = replace(config, seed=int(seed))
    if trajectory is None:
        if world.waypoints is None:
            raise InputError(f"world {world.name!r} has no waypoints; pass a trajectory")
        trajectory = trajectory_from_waypoints(world.waypoints, config.trajectory)
    bearing_ss, range_ss, odom_ss, rel_ss = np.random.SeedSequence(config.seed).spawn(4)
    rng_bearing = np.random.default_rng(bearing_ss)
    rng_range = np.random.default_rng(range_ss)

    laser, noise = config.laser, config.noise
    bearings = laser.bearings_rad()
    pose_base_laser = np.asarray(laser.pose_base_laser, dtype=np.float64)
    poses_world_laser = pose_compose(trajectory.poses_world_base, pose_base_laser)
    n, m = len(trajectory), bearings.shape[0]
    ranges = np.empty((n, m))
    true_ranges = np.empty((n, m))
    hit_ids = np.empty((n, m), dtype=np.int64)
    for start in range(0, n, SCANS_PER_CHUNK):
        stop = min(n, start + SCANS_PER_CHUNK)
        c = stop - start
        eps_phi = rng_bearing.standard_normal((c, m)) * noise.sigma_bearing_rad
        eps_unit = rng_range.standard_normal((c, m))
        pose = poses_world_laser[start:stop]
        angles = pose[:, 2:3] + bearings[None, :] + eps_phi
        origins = np.repeat(pose[:, :2], m, axis=0)
        d_true, ids = cast_rays(origins, angles.reshape(-1), world, laser.max_range_m)
        d_true = d_true.reshape(c, m)
        ids = ids.reshape(c, m)
        hit = ids >= 0
        sigma_d = noise.sigma_range_m + noise.sigma_range_per_m * d_true
        d = np.maximum(d_true + eps_unit * sigma_d, 0.0)
        no_return = ~hit | (d >= laser.max_range_m)
        ranges[start:stop] = np.where(no_return, laser.max_range_m, d)
        hit_ids[start:stop] = np.where(no_return, -1, ids)
        true_ranges[start:stop] = d_true
        if progress is not None:
            progress(stop, n)

    poses_odom_base = simulate_odometry(
        trajectory.poses_world_base, config.odometry, np.random.default_rng(odom_ss)
    )
    pairs = relation_pairs(poses_world_laser, config.relations, np.random.default_rng(rel_ss))
    return SimulatedLog(
        world=world,
        config=config,
        timestamps=trajectory.timestamps,
        poses_world_base=trajectory.poses_world_base,
        poses_odom_base=poses_odom_base,
        bearings_rad=bearings,
        ranges_m=ranges,
        hit_ids=hit_ids,
        true_ranges_m=true_ranges,
        relation_pairs=pairs,
    )
