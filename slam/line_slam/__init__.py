"""Line SLAM on a factor graph: :class:`LineSlam`, fed one scan at a time.

::

    from slam.line_slam import LineSlam, SlamConfig

    slam = LineSlam(SlamConfig(backend="isam2"))
    for scan in scans:              # slam.types.Scan, with odometry
        slam.add_scan(scan)         # or add_scan(scan, lines) with lines already extracted
    slam.optimize()
    result = slam.result()          # SlamResult: poses, covariances, line map; .write(out_dir)

The configuration classes import without gtsam; :class:`LineSlam` pulls in the back-end
(:mod:`slam.graph`) on first use.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from slam.line_slam.config import (
    FrontendConfig,
    FusionConfig,
    Isam2Config,
    KeyframeConfig,
    LoopClosureConfig,
    MotionNoiseConfig,
    RelocalisationConfig,
    SlamConfig,
    SolverConfig,
    TentativeConfig,
)

if TYPE_CHECKING:
    from slam.line_slam.pipeline import LineSlam, ScanReport, SlamWarning
    from slam.result import SlamResult

__all__ = [
    "FrontendConfig",
    "FusionConfig",
    "Isam2Config",
    "KeyframeConfig",
    "LineSlam",
    "LoopClosureConfig",
    "MotionNoiseConfig",
    "RelocalisationConfig",
    "ScanReport",
    "SlamConfig",
    "SlamResult",
    "SlamWarning",
    "SolverConfig",
    "TentativeConfig",
]

_LAZY = {
    "LineSlam": "slam.line_slam.pipeline",
    "ScanReport": "slam.line_slam.pipeline",
    "SlamWarning": "slam.line_slam.pipeline",
    "SlamResult": "slam.result",
}


def __getattr__(name: str) -> Any:
    """Import the pipeline (and with it gtsam) on first use."""
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'slam.line_slam' has no attribute {name!r}")
