"""Model-error floor on measured lines, specified at each segment's mid-point.

The weighted fit's covariance (``linefit``) only knows the per-beam range and bearing noise.
Real walls are not the ideal lines of that model: they bend, beams have a footprint, ranges are
quantised and biased by the surface.  On the real logs the fits' covariances alone make the χ²
gates so tight that the same wall, seen again a little later, fails them and is mapped twice.

The floor is an offset error ``σ_o`` along the normal at the segment's mid-point and an
independent angle error ``σ_a`` about it (the graph back-end's ``line_model_sigma_*`` on the
``real`` branch uses the same model).  With the mid-point at tangent coordinate ``s_m``
(``p = r n + s t``, ``t = (−sin α, cos α)``), a rotation ``δα`` about it changes ``r`` by
``s_m δα``, so in ``(r, α)``

``R_model = [[σ_o² + s_m² σ_a², s_m σ_a²], [s_m σ_a², σ_a²]]``.

Specifying it at the foot of the normal instead (``diag(σ_o², σ_a²)`` added to ``(r, α)``)
would give a line seen far along itself an angle error that moves the seen part by
``|s_m| σ_a`` while ``r`` stays tight: the gate would then reject the re-observation of exactly
the walls seen at grazing angles.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["model_error_covariance"]

FloatArray = NDArray[np.float64]


def model_error_covariance(
    r_alpha: FloatArray, endpoints: FloatArray, sigma_offset_m: float, sigma_angle_rad: float
) -> FloatArray:
    """Covariance ``(K, 2, 2)`` of the model error of lines, at their segments' mid-points.

    Parameters
    ----------
    r_alpha : ndarray, shape (K, 2)
        Measured lines ``(r, α)`` (any representative; ``s`` follows ``α``).
    endpoints : ndarray, shape (K, 2, 2)
        Segment end points in the same frame.
    sigma_offset_m, sigma_angle_rad : float
        ``σ_o`` (m) and ``σ_a`` (rad).

    Returns
    -------
    ndarray, shape (K, 2, 2)
    """
    z = np.asarray(r_alpha, dtype=float).reshape(-1, 2)
    mid = np.asarray(endpoints, dtype=float).reshape(-1, 2, 2).mean(axis=1)
    a = z[:, 1]
    s_m = -np.sin(a) * mid[:, 0] + np.cos(a) * mid[:, 1]
    sa2 = float(sigma_angle_rad) ** 2
    out = np.empty((z.shape[0], 2, 2))
    out[:, 0, 0] = float(sigma_offset_m) ** 2 + s_m * s_m * sa2
    out[:, 0, 1] = out[:, 1, 0] = s_m * sa2
    out[:, 1, 1] = sa2
    return out
