"""Simulated laser logs with ground truth.

Worlds of line segments, exact ray casting with the paper's noise model (Section II), noisy
odometry, relations.

Main entry points::

    from slam.sim import SimConfig, get_world, simulate, write_simulation

    world = get_world("loop")                       # or load_world("path/world.json")
    log = simulate(world, None, SimConfig(), seed=0)  # None: the world's default path
    write_simulation(log, "out/")                   # log.clf, ground_truth.tum, relations.txt, ...
"""

from slam.sim.config import (
    LaserConfig,
    LaserNoiseConfig,
    OdometryNoiseConfig,
    RelationsConfig,
    SimConfig,
    TrajectoryConfig,
)
from slam.sim.odometry import (
    integrate_motions,
    motion_noise_covariance,
    noisy_motions,
    relative_motions,
    simulate_odometry,
)
from slam.sim.raycast import cast_rays, cast_scan
from slam.sim.trajectory import SimTrajectory, trajectory_from_waypoints
from slam.sim.world import World, WorldBuilder, read_world, write_world
from slam.sim.worlds import WORLD_NAMES, get_world, load_world

__all__ = [
    "WORLD_NAMES",
    "LaserConfig",
    "LaserNoiseConfig",
    "OdometryNoiseConfig",
    "RelationsConfig",
    "SimConfig",
    "SimTrajectory",
    "TrajectoryConfig",
    "World",
    "WorldBuilder",
    "cast_rays",
    "cast_scan",
    "get_world",
    "integrate_motions",
    "load_world",
    "motion_noise_covariance",
    "noisy_motions",
    "read_world",
    "relative_motions",
    "simulate_odometry",
    "trajectory_from_waypoints",
    "write_world",
]
