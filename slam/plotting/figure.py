"""pyplot on the Agg backend (files, no windows) and saving a finished figure."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

__all__ = ["plt", "save_figure"]


def save_figure(
    fig: Any,
    path: str | Path,
    dpi: int,
    *,
    tight_layout: bool = True,
    bbox_inches: str | None = None,
) -> Path:
    """Write ``fig`` to ``path`` (format from the suffix) and close it.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The finished figure.
    path : str or Path
        Output file; its folder is created.
    dpi : int
        Resolution (dots per inch).
    tight_layout : bool
        Lay the axes out tightly before saving.
    bbox_inches : str, optional
        ``"tight"`` crops the saved image to its content.

    Returns
    -------
    Path
        ``path``.
    """
    out = Path(path)
    if tight_layout:
        fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=dpi, bbox_inches=bbox_inches)
    plt.close(fig)
    return out
