"""EKF-SLAM baseline with line landmarks (filterpy), fed scans like the graph back-end.

Public API: :class:`EkfSlam` (the filter), :class:`EkfConfig` (its settings, TOML table
``[ekf]``).  :meth:`EkfSlam.result` returns a :class:`slam.result.SlamResult`, the result type
(trajectory, map, covariances, statistics, files) of both estimators.

The names are imported on first use (as in :mod:`slam.graph`): ``slam.config`` needs only
:class:`EkfConfig`, and importing the filter pulls in filterpy and with it ``scipy.stats``
(about a second), which every ``lineslam`` command would otherwise pay at start-up.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from slam.ekf.config import EkfConfig, MotionNoiseConfig
    from slam.ekf.ekf_slam import EkfSlam
    from slam.ekf.records import ScanReport

__all__ = ["EkfConfig", "EkfSlam", "MotionNoiseConfig", "ScanReport"]

_LAZY = {
    "EkfConfig": "slam.ekf.config",
    "EkfSlam": "slam.ekf.ekf_slam",
    "MotionNoiseConfig": "slam.ekf.config",
    "ScanReport": "slam.ekf.records",
}


def __getattr__(name: str) -> Any:
    """Import a public name from its module on first use."""
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'slam.ekf' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value
