"""``lineslam export DIR --format FORMAT --out PATH``: files for other tools, from a results DIR.

Formats (:mod:`slam.export`): ``occupancy`` (map_server ``PATH.pgm`` + ``PATH.yaml``,
ray-traced from the run's log at the estimated poses, ``--resolution`` m per cell),
``geojson`` (the line map), ``svg`` (line map and trajectory), ``g2o`` (the factor graph of
``lineslam slam``), ``tum`` (the trajectory).  The files are written under temporary names
and renamed into place when complete: an interrupted or failed export leaves an earlier file
as it was.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from slam.cli._app import app
from slam.cli.common import out_path

__all__ = ["export"]


@app.command("export")
def export(
    results_dir: Annotated[Path, typer.Argument(help="Results folder of slam, ekf or map.")],
    fmt: Annotated[
        str,
        typer.Option("--format", help="occupancy, geojson, svg, g2o or tum."),
    ],
    out: Annotated[
        Path,
        typer.Option(
            "--out",
            parser=out_path,
            help="Output file (occupancy: PATH gives PATH.pgm and PATH.yaml); written whole or "
            "not at all.",
        ),
    ],
    resolution: Annotated[
        float, typer.Option("--resolution", help="Occupancy grid cell size (m).")
    ] = 0.05,
    log: Annotated[
        str | None,
        typer.Option("--log", help="The run's log, if not where summary.json says."),
    ] = None,
    min_distance: Annotated[
        float,
        typer.Option("--every-m", help="Occupancy: use a scan when the laser moved this far (m)."),
    ] = 0.1,
    min_angle: Annotated[
        float,
        typer.Option("--every-rad", help="Occupancy: ... or turned this much (rad)."),
    ] = 0.1,
    quiet: Annotated[bool, typer.Option("--quiet", help="Print nothing.")] = False,
) -> None:
    """Export a results folder: occupancy grid, line map (GeoJSON, SVG), graph (g2o), TUM."""
    from slam.cli.scanner_opts import echo_warnings
    from slam.diagnostics import tally_warnings
    from slam.export import export_results

    with tally_warnings() as tally:
        paths = export_results(
            results_dir,
            fmt,
            out,
            resolution_m=resolution,
            log=log,
            min_distance_m=min_distance,
            min_angle_rad=min_angle,
        )
    echo_warnings(tally)
    if not quiet:
        typer.echo("wrote " + ", ".join(str(p) for p in paths))
