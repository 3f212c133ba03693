"""The scans' own noise against the sensor model: a check of ``[linefit.noise]``.

Every point's covariance comes from the paper's noise model (Eq. 8) with the configured
``sigma_range_m`` and ``sigma_bearing_rad``.  A log whose scanner is noisier, or whose ranges
were written coarsely, then gets covariances that are too small, and nothing in the run says
so: the
estimated line model error (``[slam] line_model_error``) absorbs part of it in the back end,
but not in the scan matcher or in the fits that ``linefit`` users make themselves.

:class:`RangeNoiseCheck` collects each keyframe's :attr:`ScanPoints.noise_ratio
<slam.frontend.scan_match.ScanPoints.noise_ratio>` (how its points scatter about their short
local lines, against Eq. 8) and reports the median's square root, ``sigma_ratio``, in
``summary.json`` (``range_noise``).  Straight walls scanned as Eq. 8 says give about 1 (the
simulated demo: 1.03), Gaussian range noise ``k`` times ``sigma_range_m`` about ``k``; wall
texture, clutter or a noisier scanner give more.  Above
:data:`WARN_SIGMA_RATIO` the run warns once.  Nothing in the estimate changes: the check
reports, the configuration decides.
"""

from __future__ import annotations

import bisect
import math

from slam.frontend.scan_match import ScanPoints

__all__ = ["WARN_SIGMA_RATIO", "RangeNoiseCheck", "warn_range_noise"]

WARN_SIGMA_RATIO = 3.0
"""``sigma_ratio`` above which the run warns: the points scatter three times (in variance nine
times) as much as ``[linefit.noise]`` says.  The default runs of the catalogued logs read
1.18 (Intel), 1.94 (fr079) and 6.09 (ACES, whose ranges are written in steps of about 2.5 cm
below 2 m and 5 cm beyond: docs/real-logs.md)."""

MIN_KEYFRAMES = 20
"""Keyframes with a ratio before the check reports one (a median of fewer says little)."""


def warn_range_noise(sigma_ratio: float, sigma_range_m: float, keyframes: int) -> str:
    """The warning for scans that scatter ``sigma_ratio`` times as much as Eq. 8 says."""
    return (
        f"the scans' points scatter about their local lines {sigma_ratio:.1f} times as much as "
        f"the sensor noise model says (median of {keyframes} keyframes; sigma_range_m = "
        f"{sigma_range_m:g} m): a noisier scanner, rough walls or coarsely written ranges. "
        f"The points scatter as if sigma_range_m were {sigma_ratio * sigma_range_m:.3g} m, "
        "and their covariances (and the lines') are smaller than that scatter"
    )


class RangeNoiseCheck:
    """Collects the keyframes' noise ratios (module docstring).

    Parameters
    ----------
    sigma_range_m : float
        The configured range noise (for the summary and the warning).
    """

    def __init__(self, sigma_range_m: float) -> None:
        self.sigma_range_m = float(sigma_range_m)
        self._ratios: list[float] = []  # sorted: the median is read at every keyframe
        self.warned = False

    def add(self, points: ScanPoints) -> None:
        """Count a keyframe's points (a NaN ratio, no window to measure, is left out)."""
        if math.isfinite(points.noise_ratio):
            bisect.insort(self._ratios, float(points.noise_ratio))

    @property
    def keyframes(self) -> int:
        """Keyframes with a ratio."""
        return len(self._ratios)

    @property
    def sigma_ratio(self) -> float | None:
        """Square root of the median ratio; None before :data:`MIN_KEYFRAMES` keyframes."""
        n = len(self._ratios)
        if n < MIN_KEYFRAMES:
            return None
        r = self._ratios
        median = r[n // 2] if n % 2 else (r[n // 2 - 1] + r[n // 2]) / 2.0  # as np.median
        return math.sqrt(max(median, 0.0))

    def warning(self) -> str | None:
        """The warning, the first time the ratio is above :data:`WARN_SIGMA_RATIO`; else None."""
        ratio = self.sigma_ratio
        if self.warned or ratio is None or ratio <= WARN_SIGMA_RATIO:
            return None
        self.warned = True
        return warn_range_noise(ratio, self.sigma_range_m, self.keyframes)

    def summary(self) -> dict[str, float | int | None]:
        """``summary.json``'s ``range_noise``."""
        return {
            "sigma_ratio": self.sigma_ratio,
            "keyframes": self.keyframes,
            "sigma_range_m": self.sigma_range_m,
            "warn_above": WARN_SIGMA_RATIO,
        }
