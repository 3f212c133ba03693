"""Benchmark the simulator: vectorised ray casting vs a per-ray loop, and whole simulations.

Prints throughput (rays/s, scans/s) and the speed-up of the vectorised caster over a plain
per-ray numpy loop measured side by side in the same run.

    .venv/bin/python scripts/bench_sim.py
"""

from __future__ import annotations

import time

import numpy as np

from slam.sim import LaserConfig, SimConfig, cast_rays, get_world
from slam.sim.simulate import simulate
from slam.sim.trajectory import trajectory_from_waypoints


def per_ray_loop(origins: np.ndarray, angles: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Baseline: one ray at a time, vectorised over segments only."""
    a = segments[:, 0]
    e = segments[:, 1] - a
    out = np.full(angles.shape[0], np.inf)
    for k in range(angles.shape[0]):
        d = np.array([np.cos(angles[k]), np.sin(angles[k])])
        w = a - origins[k]
        den = d[0] * e[:, 1] - d[1] * e[:, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (w[:, 0] * e[:, 1] - w[:, 1] * e[:, 0]) / den
            u = (w[:, 0] * d[1] - w[:, 1] * d[0]) / den
        ok = (den != 0) & (t > 1e-9) & (u >= 0) & (u <= 1)
        if ok.any():
            out[k] = t[ok].min()
    return out


def best_of(fn, repeats: int = 3) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> None:
    world = get_world("loop")
    traj = trajectory_from_waypoints(world.waypoints)
    rng = np.random.default_rng(0)
    n_rays = 20_000
    k = rng.integers(0, len(traj), n_rays)
    origins = traj.poses_world_base[k, :2]
    angles = rng.uniform(-np.pi, np.pi, n_rays)
    sub = 2_000
    t_vec = best_of(lambda: cast_rays(origins, angles, world))
    t_loop = best_of(lambda: per_ray_loop(origins[:sub], angles[:sub], world.segments), 1)
    ranges, _ = cast_rays(origins[:sub], angles[:sub], world)
    assert np.allclose(ranges, per_ray_loop(origins[:sub], angles[:sub], world.segments))
    vec_rate = n_rays / t_vec
    loop_rate = sub / t_loop
    print(f"world loop: {len(world)} segments")
    print(f"cast_rays (vectorised): {vec_rate:12,.0f} rays/s")
    print(f"per-ray loop baseline:  {loop_rate:12,.0f} rays/s")
    print(f"ratio vectorised / loop: {vec_rate / loop_rate:.1f}x")
    for laser in (LaserConfig(), LaserConfig.paper()):
        config = SimConfig(laser=laser)
        t = best_of(lambda c=config: simulate(world, traj, c, seed=0))
        print(
            f"simulate loop, {laser.n_beams} beams: {len(traj) / t:8,.0f} scans/s "
            f"({len(traj)} scans in {t:.2f} s)"
        )


if __name__ == "__main__":
    main()
