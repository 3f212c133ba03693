"""``lineslam datasets``: the registered datasets, and whether each is present and intact."""

from __future__ import annotations

import json
from typing import Annotated

import typer

from slam.cli._app import app
from slam.io.catalog import catalog_path, data_root, load_catalog, verify_dataset

__all__ = ["datasets"]


@app.command("datasets")
def datasets(
    check: Annotated[
        bool,
        typer.Option("--check/--no-check", help="Verify sizes and sha256 checksums."),
    ] = True,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON instead of a table.")] = False,
) -> None:
    """List the registered datasets (intel, aces, fr079): files, sensor facts, status.

    Data root: $LINESLAM_DATA, else <repository>/../shared/datasets.
    """
    root = data_root()
    catalog = load_catalog()
    rows = []
    for manifest in catalog.values():
        status = verify_dataset(manifest, root, checksum=check)
        rows.append((manifest, status))
    if as_json:
        out = {
            "data_root": str(root),
            "catalog": str(catalog_path()),
            "datasets": [
                {**status.to_dict(), "manifest": manifest.to_dict()} for manifest, status in rows
            ],
        }
        typer.echo(json.dumps(out, indent=2))
        return
    typer.echo(f"data root: {root}")
    header = f"{'name':<7} {'scans':>6} {'beams':>5} {'max range':>9}  {'status':<14} title"
    typer.echo(header)
    for manifest, status in rows:
        if not status.present:
            state = "missing"
        elif status.intact is None:
            state = "present"
        else:
            state = "intact" if status.intact else "CHANGED"
        typer.echo(
            f"{manifest.name:<7} {manifest.scans:>6} {manifest.laser.beams:>5} "
            f"{manifest.laser.max_range_m:>8.2f}m  {state:<14} {manifest.title}"
        )
        for problem in status.problems:
            typer.echo(f"        {problem}")
