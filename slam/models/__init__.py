"""Models shared by both estimators (numpy only).

Odometry noise and the keyframe rule (:mod:`slam.models.motion`), the anchored line chart
(:mod:`slam.models.anchored`).
"""

from slam.models.anchored import (
    anchored_from_r_alpha,
    anchored_jacobian,
    drift_covariance,
    landmarks_normal_form,
    model_error_covariance,
    observe_anchored,
    r_alpha_from_anchored,
)
from slam.models.motion import MotionNoiseConfig, moved_enough

__all__ = [
    "MotionNoiseConfig",
    "anchored_from_r_alpha",
    "anchored_jacobian",
    "drift_covariance",
    "landmarks_normal_form",
    "model_error_covariance",
    "moved_enough",
    "observe_anchored",
    "r_alpha_from_anchored",
]
