"""``lineslam simulate WORLD --out DIR``: a simulated CARMEN log with ground truth."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import typer

from slam.cli._app import app
from slam.cli.common import ConfigOpt, QuietOpt, SeedOpt, SigmaDOpt, SigmaPhiOpt, out_path
from slam.errors import ConfigError
from slam.io.atomic import check_output_dir, staged_dir
from slam.sim.config import LaserConfig, SimConfig
from slam.sim.simulate import simulate
from slam.sim.worlds import WORLD_NAMES, load_world
from slam.sim.write import write_simulation

__all__ = ["simulate_command"]


def build_sim_config(
    config_path: Path | None,
    world: str | None = None,
    seed: int | None = None,
    sigma_d: float | None = None,
    sigma_phi: float | None = None,
    beams: int | None = None,
    step_deg: float | None = None,
    first_angle_deg: float | None = None,
    paper_laser: bool = False,
    max_range: float | None = None,
    spacing: float | None = None,
    speed: float | None = None,
    odom_sigma_trans: float | None = None,
    odom_sigma_rot: float | None = None,
    heading_drift: float | None = None,
    scale_bias: float | None = None,
) -> SimConfig:
    """``--config`` (or the defaults) with the command-line overrides applied."""
    config = SimConfig.from_toml(config_path) if config_path is not None else SimConfig()
    if world is not None:
        config = replace(config, world=world)
    if seed is not None:
        config = replace(config, seed=seed)
    config = config.with_sensor_noise(sigma_d, sigma_phi)
    laser = LaserConfig.paper() if paper_laser else config.laser
    laser_changes: dict[str, Any] = {
        k: v
        for k, v in {
            "n_beams": beams,
            "step_deg": step_deg,
            "first_angle_deg": first_angle_deg,
            "max_range_m": max_range,
        }.items()
        if v is not None
    }
    config = replace(config, laser=replace(laser, **laser_changes))
    traj_changes: dict[str, Any] = {
        k: v for k, v in {"scan_spacing_m": spacing, "speed_m_s": speed}.items() if v is not None
    }
    config = replace(config, trajectory=replace(config.trajectory, **traj_changes))
    odom_changes: dict[str, Any] = {
        k: v
        for k, v in {
            "sigma_trans_per_m": odom_sigma_trans,
            "sigma_rot_per_m": odom_sigma_rot,
            "heading_drift_rad_per_m": heading_drift,
            "scale_bias": scale_bias,
        }.items()
        if v is not None
    }
    return replace(config, odometry=replace(config.odometry, **odom_changes))


@app.command("simulate")
def simulate_command(
    out: Annotated[
        Path,
        typer.Option(
            "--out",
            parser=out_path,
            help="Output folder (created, or an earlier one replaced whole).",
        ),
    ],
    world: Annotated[
        str | None,
        typer.Argument(
            help=f"A named world (corridor_loop, gridNxM, {', '.join(WORLD_NAMES)}) or a "
            "world.json; default: the config's world.",
            show_default=False,
        ),
    ] = None,
    config_path: ConfigOpt = None,
    sigma_d: SigmaDOpt = None,
    sigma_phi: SigmaPhiOpt = None,
    seed: SeedOpt = None,
    quiet: QuietOpt = False,
    beams: Annotated[int | None, typer.Option("--beams", help="Beams per scan (180).")] = None,
    step_deg: Annotated[
        float | None, typer.Option("--step-deg", help="Angle between beams (deg; 1).")
    ] = None,
    first_angle_deg: Annotated[
        float | None, typer.Option("--first-angle-deg", help="Bearing of beam 0 (deg; -90).")
    ] = None,
    paper_laser: Annotated[
        bool,
        typer.Option("--paper-laser", help="720 beams, 0.25° over 180° (the paper's scans)."),
    ] = False,
    max_range: Annotated[
        float | None, typer.Option("--max-range", help="No-return reading (m; 80).")
    ] = None,
    spacing: Annotated[
        float | None, typer.Option("--spacing", help="Distance between scans (m; 0.3).")
    ] = None,
    speed: Annotated[float | None, typer.Option("--speed", help="Robot speed (m/s; 0.4).")] = None,
    odom_sigma_trans: Annotated[
        float | None,
        typer.Option("--odom-sigma-trans", help="Odometry translation noise (m per √m)."),
    ] = None,
    odom_sigma_rot: Annotated[
        float | None,
        typer.Option("--odom-sigma-rot", help="Odometry heading noise per metre (rad per √m)."),
    ] = None,
    heading_drift: Annotated[
        float | None,
        typer.Option("--heading-drift", help="Systematic odometry heading drift (rad/m)."),
    ] = None,
    scale_bias: Annotated[
        float | None,
        typer.Option("--scale-bias", help="Systematic odometry distance error (fraction)."),
    ] = None,
    no_beam_hits: Annotated[
        bool, typer.Option("--no-beam-hits", help="Do not write beam_hits.npy.")
    ] = False,
) -> None:
    """Simulate a laser log in WORLD; write log.clf, ground_truth.tum, relations.txt, ...

    Files in DIR: log.clf (CARMEN), ground_truth.tum (true laser poses), relations.txt
    (relations from the ground truth), world.json, beam_hits.npy (segment id per beam, -1 = no
    return), odometry.tum, config.toml (reload with --config).
    """
    if config_path is None and world is None:
        raise ConfigError("give a WORLD (a named world or a world.json) or --config")
    config = build_sim_config(
        config_path,
        world,
        seed,
        sigma_d,
        sigma_phi,
        beams,
        step_deg,
        first_angle_deg,
        paper_laser,
        max_range,
        spacing,
        speed,
        odom_sigma_trans,
        odom_sigma_rot,
        heading_drift,
        scale_bias,
    )
    check_output_dir(out)
    from slam.experiments.linesim import ray_world

    the_world = ray_world(config.world) or load_world(config.world)
    bar = None
    if not quiet:
        from tqdm import tqdm

        bar = tqdm(total=0, unit="scan", desc=f"simulate {the_world.name}", leave=False)

    def progress(done: int, total: int) -> None:
        if bar is not None:
            bar.total = total
            bar.update(done - bar.n)

    try:
        log = simulate(the_world, None, config, progress=progress)
    finally:
        if bar is not None:
            bar.close()
    with staged_dir(out) as work:
        written = write_simulation(log, work, beam_hits=not no_beam_hits, final_dir=out)
    paths = {role: out / path.name for role, path in written.items()}
    if not quiet:
        no_return = float(np.mean(log.hit_ids < 0))
        drift = float(np.linalg.norm(log.poses_odom_base[-1, :2] - log.poses_world_base[-1, :2]))
        path_m = float(np.linalg.norm(np.diff(log.poses_world_base[:, :2], axis=0), axis=1).sum())
        typer.echo(
            f"{the_world.name}: {log.n_scans} scans x {log.n_beams} beams over {path_m:.1f} m "
            f"({log.timestamps[-1] - log.timestamps[0]:.1f} s), no-return {no_return:.1%}, "
            f"odometry end error {drift:.2f} m, {len(log.relation_pairs)} relations"
        )
        for role, path in paths.items():
            typer.echo(f"  {role:13s} {path}")
