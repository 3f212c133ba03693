"""linefit: maximum-likelihood weighted line fitting for one 2D range scan.

Implements Pfister, Roumeliotis & Burdick, *Weighted Line Fitting Algorithms for Mobile Robot Map
Building and Efficient Data Representation* (ICRA 2003), Sections II-IV.  The one call is
:func:`extract_lines`.  This package depends only on numpy and scipy (no gtsam, filterpy,
matplotlib or CLI code).
"""

from linefit.config import LineFitConfig, SensorNoiseConfig
from linefit.errors import ConfigError, DegenerateGeometryError, InputError, LineslamError
from linefit.line import Line, normal_form, wrap_angle

__all__ = [
    "ConfigError",
    "DegenerateGeometryError",
    "InputError",
    "Line",
    "LineFitConfig",
    "LineslamError",
    "SensorNoiseConfig",
    "normal_form",
    "wrap_angle",
]
