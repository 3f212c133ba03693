"""Lines across poses (paper Sec. V): transforms, χ² merge test, fusion, map building.

Transforms with covariance (Eq. 31), the χ² merge test (Eqs. 34-35), maximum-likelihood
fusion (Eqs. 36-37), segment handling and map building.

numpy/scipy only (no gtsam, no plotting).  See ``docs/lines.md`` for the conventions.
"""

from slam.lines.merge import (
    DEFAULT_GATE_PROBABILITY,
    align_representative,
    chi2_gate,
    chi2_ppf,
    extent_gap,
    fuse,
    fuse_many,
    fuse_pair_unchecked,
    is_compatible,
    mahalanobis2,
    mahalanobis2_unchecked,
    to_normal_form,
    unite_segments,
)
from slam.lines.transform import (
    adjoint,
    between_poses,
    compose_chain,
    compound_poses,
    invert_pose,
    line_from_world,
    line_to_world,
    segment_shift,
    transform_line,
    transform_line_to_child,
    transform_segments,
)

__all__ = [
    "DEFAULT_GATE_PROBABILITY",
    "adjoint",
    "align_representative",
    "between_poses",
    "chi2_gate",
    "chi2_ppf",
    "compose_chain",
    "compound_poses",
    "extent_gap",
    "fuse",
    "fuse_many",
    "fuse_pair_unchecked",
    "invert_pose",
    "is_compatible",
    "line_from_world",
    "line_to_world",
    "mahalanobis2",
    "mahalanobis2_unchecked",
    "segment_shift",
    "to_normal_form",
    "transform_line",
    "transform_line_to_child",
    "transform_segments",
    "unite_segments",
]
