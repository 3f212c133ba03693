"""Write a simulated log and its ground truth to a folder (``lineslam simulate --out DIR``).

Files (``INTERFACES.md``)::

    log.clf            CARMEN log: ODOM + FLASER lines (ROBOTLASER1 for other laser geometries)
    ground_truth.tum   true laser poses in the world, one per scan, stamps = the log's
    relations.txt      Kümmerle-style relations t1 t2 x y z roll pitch yaw from the ground truth
    world.json         the world's segments (with ids) and waypoints
    beam_hits.npy      int32 (n_scans, n_beams): id of the segment each beam hit, -1 = no return
    odometry.tum       the odometry's laser poses (the odometry-only baseline), same stamps
    config.toml        the SimConfig used (reload with --config); its ``world`` is the world's
                       name, or the path of the world.json written here when the simulated world
                       is not the one ``config.world`` names
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from slam.errors import InputError
from slam.io.carmen_write import CarmenWriteStats, write_carmen
from slam.io.relations import relations_from_trajectory, write_relations
from slam.io.tum import write_tum
from slam.sim.simulate import SimulatedLog
from slam.sim.world import World, write_world
from slam.sim.worlds import load_world

__all__ = ["SIM_FILES", "write_simulation"]

#: File names written by :func:`write_simulation`, by role.
SIM_FILES: dict[str, str] = {
    "log": "log.clf",
    "ground_truth": "ground_truth.tum",
    "relations": "relations.txt",
    "world": "world.json",
    "beam_hits": "beam_hits.npy",
    "odometry": "odometry.tum",
    "config": "config.toml",
}


def write_simulation(
    log: SimulatedLog,
    out_dir: str | Path,
    *,
    beam_hits: bool = True,
    final_dir: str | Path | None = None,
) -> dict[str, Path]:
    """Write ``log`` to ``out_dir`` (created); return the paths written by role.

    Parameters
    ----------
    log : SimulatedLog
        The result of :func:`slam.sim.simulate.simulate`.
    out_dir
        Folder to write to (created with its parents).
    beam_hits : bool
        Also write ``beam_hits.npy`` (large for long logs).
    final_dir
        Where the folder will be read from, if it is written elsewhere first (a temporary
        folder moved into place): ``config.toml`` then refers to ``final_dir/world.json``.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {role: out / name for role, name in SIM_FILES.items()}
    if not beam_hits:
        del paths["beam_hits"]
    config = log.config
    describe = (
        f"lineslam simulate: world {log.world.name!r}, seed {config.seed}, {log.n_scans} scans, "
        f"{log.n_beams} beams, sigma_d {config.noise.sigma_range_m} m, "
        f"sigma_phi {config.noise.sigma_bearing_rad} rad"
    )
    stats: CarmenWriteStats = write_carmen(
        paths["log"],
        log.scans(),
        range_decimals=config.laser.range_decimals,
        hostname="lineslam-sim",
        header=(describe, "ground truth (laser poses in the world): ground_truth.tum"),
    )
    assert stats.scans == log.n_scans
    write_tum(
        paths["ground_truth"],
        log.timestamps,
        log.poses_world_laser,
        header=f"{describe}\nground truth: pose of the laser in the world frame",
    )
    write_tum(
        paths["odometry"],
        log.timestamps,
        log.poses_odom_laser,
        header=f"{describe}\nodometry: pose of the laser in the odometry frame (as in log.clf)",
    )
    pairs = log.relation_pairs
    rel = relations_from_trajectory(log.timestamps, log.poses_world_laser, pairs)
    write_relations(paths["relations"], rel.t1, rel.t2, rel.poses)
    write_world(log.world, paths["world"])
    if beam_hits:
        np.save(paths["beam_hits"], log.hit_ids.astype(np.int32))
    world_json = Path(final_dir) / SIM_FILES["world"] if final_dir is not None else paths["world"]
    world_ref = _world_reference(config.world, log.world, world_json)
    replace(config, world=world_ref).to_toml(paths["config"])
    return paths


def _world_reference(name_or_path: str, world: World, written: Path) -> str:
    """``name_or_path`` if it loads ``world`` itself, else the ``world.json`` just written."""
    try:
        named = load_world(name_or_path)
    except InputError:
        return str(written)
    same = named.segments.shape == world.segments.shape and (
        np.array_equal(named.segments, world.segments) and np.array_equal(named.ids, world.ids)
    )
    return name_or_path if same else str(written)
