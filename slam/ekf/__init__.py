"""EKF-SLAM baseline with line landmarks (filterpy), fed scans like the graph back-end.

Public API: :class:`EkfSlam` (the filter), :class:`EkfConfig` (its settings, TOML table
``[ekf]``), :class:`EkfResult` (trajectory, map, covariances, statistics, files).

The names are imported on first use (as in :mod:`slam.graph`): ``slam.config`` needs only
:class:`EkfConfig`, and importing the filter pulls in filterpy and with it ``scipy.stats``
(about a second), which every ``lineslam`` command would otherwise pay at start-up.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from slam.ekf.config import EkfConfig, MotionNoiseConfig
    from slam.ekf.ekf_slam import EkfSlam, ScanReport
    from slam.ekf.result import EkfResult

__all__ = ["EkfConfig", "EkfResult", "EkfSlam", "MotionNoiseConfig", "ScanReport"]

_LAZY = {
    "EkfConfig": "slam.ekf.config",
    "EkfResult": "slam.ekf.result",
    "EkfSlam": "slam.ekf.ekf_slam",
    "MotionNoiseConfig": "slam.ekf.config",
    "ScanReport": "slam.ekf.ekf_slam",
}


def __getattr__(name: str) -> Any:
    """Import a public name from its module on first use."""
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'slam.ekf' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value
