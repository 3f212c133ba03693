"""EKF-SLAM baseline with line landmarks (filterpy), fed scans like the graph back-end.

Public API: :class:`EkfSlam` (the filter), :class:`EkfConfig` (its settings, TOML table
``[ekf]``), :class:`EkfResult` (trajectory, map, covariances, statistics, files).
"""

from slam.ekf.config import EkfConfig, MotionNoiseConfig
from slam.ekf.ekf_slam import EkfSlam, ScanReport
from slam.ekf.result import EkfResult

__all__ = ["EkfConfig", "EkfResult", "EkfSlam", "MotionNoiseConfig", "ScanReport"]
