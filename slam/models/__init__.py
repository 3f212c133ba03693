"""Models shared by both estimators (numpy only): odometry noise, the anchored line chart."""

from slam.models.anchored import (
    anchored_from_r_alpha,
    anchored_jacobian,
    drift_covariance,
    landmarks_normal_form,
    model_error_covariance,
    observe_anchored,
    r_alpha_from_anchored,
)
from slam.models.motion import MotionNoiseConfig

__all__ = [
    "MotionNoiseConfig",
    "anchored_from_r_alpha",
    "anchored_jacobian",
    "drift_covariance",
    "landmarks_normal_form",
    "model_error_covariance",
    "observe_anchored",
    "r_alpha_from_anchored",
]
