"""slam: line maps and line-based SLAM across poses.

Layers (lower never imports higher): ``slam.geometry`` / ``slam.lines`` (transform, χ² merge,
fusion; numpy only) → ``slam.io``, ``slam.sim``, ``slam.evaluation`` → ``slam.graph`` (GTSAM
back-end), ``slam.ekf`` (filterpy baseline) → ``slam.runner`` (reads logs, writes results) →
``slam.cli`` (typer).  Plotting lives in ``slam.plotting`` and is imported only where a picture
is drawn.

Importing :mod:`slam` selects OpenBLAS's kernels for results that do not depend on the CPU
(:mod:`slam.blas`; it must come before numpy's import for that).
"""

from slam import blas as _blas

_blas.select_kernels()

__version__ = "0.1.0"
