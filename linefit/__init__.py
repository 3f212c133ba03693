"""linefit: maximum-likelihood weighted line fitting for one 2D range scan.

Implements Pfister, Roumeliotis & Burdick, *Weighted Line Fitting Algorithms for Mobile Robot Map
Building and Efficient Data Representation* (ICRA 2003), Sections II-IV.  The one call is
:func:`extract_lines`.  This package depends only on numpy, scipy and numba (no gtsam,
filterpy, matplotlib or CLI code).
"""

from linefit.config import LineFitConfig, SensorNoiseConfig
from linefit.errors import ConfigError, DegenerateGeometryError, InputError, LineslamError
from linefit.extract import extract_lines, extract_lines_batch, fit_line, fit_scan_line
from linefit.line import Line, normal_form, wrap_angle
from linefit.noise import point_covariances

__all__ = [
    "ConfigError",
    "DegenerateGeometryError",
    "InputError",
    "Line",
    "LineFitConfig",
    "LineslamError",
    "SensorNoiseConfig",
    "extract_lines",
    "extract_lines_batch",
    "fit_line",
    "fit_scan_line",
    "normal_form",
    "point_covariances",
    "wrap_angle",
]
