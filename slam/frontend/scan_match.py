"""Dense scan matching: a keyframe's points registered against the previous keyframe's.

The lines of a scan constrain its pose only where there are lines, and a line registration
needs lines that the local map already holds.  Where lines are few, parallel or new, and
where the wheel odometry slips (a turn misreported by tens of degrees), every point of the
scan still carries information: the scan is registered against the previous keyframe's
points, point to line (each reference point's local line from its neighbours in beam
order), each residual weighted by the paper's per-point noise (Eq. 8) plus the walls' model
error, with Cauchy weights, and the odometry step as a Gaussian prior.  The result is the
posterior mode of the relative pose between the two keyframes and its covariance.

**Search.**  Point-to-line iterations converge only from a few degrees; a slip can be tens
of degrees.  The match therefore starts from the odometry and from rotations of it over
``rotation_window_rad`` (steps of ``rotation_step_rad``), runs a few iterations from each,
refines the odometry's own start and the two other starts of most overlap, and keeps
the refined one of least negative log-posterior (Cauchy cost of the pairs, an outlier's cost
for each unpaired point, and the prior).  The points' summed cost treats them as independent
and so overstates their evidence; it is divided by ``κ = tr(H C)/3`` (``H`` its curvature,
``C`` the sandwich covariance below), the magnitude adjustment of a composite likelihood
(Chandler & Bate 2007), before it is weighed against the prior.

**Slips.**  With ``slip_probability > 0`` the odometry's heading is a mixture: its Gaussian, or
with that probability a slip (``slip_sigma_rad`` more spread in rotation, and with it the
translation the odometry integrated along the slipped heading, :func:`slip_covariance`).  The
search weighs the starts under the mixture; the component more probable at the match is then
its prior (a max-mixture, Olson & Agarwal 2012): a slip's match keeps the rotation the points
say, and :attr:`ScanMatch.slip` tells the caller that the odometry's rotation did not hold.

**Covariance.**  The points' part is the Cauchy M-estimator's sandwich ``A⁻¹ B A⁻¹`` in
expectation under the noise model (``A = E[ψ'] Σ JᵀJ/σ²``; in ``B`` the model error is one
offset shared by the points on one piece of reference wall, so that many points on one wall
weigh as one wall); it is combined with the prior's information.  A known limit
(``tests/test_scan_match.py``): with noisy ranges the tilt of the short local lines reads as
information along a corridor's axis, so the covariance there is too small;
``normal_length_m`` extends the lines along the walls and removes it (not the default).

:func:`scan_points` makes the points of a scan; :func:`match_scans` matches two;
:func:`match_any_heading` matches two with nothing known of the rotation between them.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import ClassVar, Literal

import numpy as np
from numba import njit
from numpy.typing import NDArray

from linefit.config import SensorNoiseConfig
from linefit.noise import point_covariance_entries
from slam import interrupts
from slam.geometry import pose_between, pose_log
from slam.validate import nonneg, positive, require

__all__ = [
    "CAUCHY_DPSI",
    "CAUCHY_PSI2",
    "ScanMatch",
    "ScanMatchConfig",
    "ScanPoints",
    "contradicted_covariance",
    "match_any_heading",
    "match_scans",
    "normal_half_window",
    "overlap_at",
    "refine_scan",
    "scale_points_information",
    "scan_points",
    "scan_view",
    "slip_covariance",
    "visible_points",
]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class ScanMatchConfig:
    """Dense scan matching between consecutive keyframes (``[slam.frontend.scan_matching]``).

    Attributes
    ----------
    enabled : bool
        Match each keyframe's points against the previous keyframe's with the odometry step as
        the prior; an accepted match is the keyframe's prediction (the graph keeps the odometry
        factor, unless the match finds a slip, and the line factors).  False: the odometry
        alone predicts.
    model_sigma_m : float
        The walls' model error along a reference line's normal (m), added to the Eq. 8
        variance of every residual.
    normal_span_rad : float
        A reference point's local line is fitted to the points of this angle of the scan
        centred on it (rad): ``2h + 1`` consecutive points with ``h`` the nearest whole number
        of beam steps to half the angle, at least one (the 2° default: five points at 0.5°
        beam spacing, three at 1° and coarser), so that it covers the same piece of wall
        whatever the scanner's beam density.
    normal_length_m : float
        A reference point's local line is then extended, point by point on either side, to
        the points within half this distance of it (m), as long as no two consecutive ones
        are further apart than ``max_neighbour_gap_m``, the longer line stays thin
        (``max_line_thickness``) and its points lie on it within their Eq. 8 noise (χ², 99 %;
        the noise scaled up where the scan's short lines show it larger than Eq. 8 says);
        else half the distance is tried, down to the short line.  The tilt of a line through a
        few noisy points otherwise reads as information along the wall: in a corridor the
        posterior along its axis is then a fraction of the odometry's.  0 (default): the
        short line alone; 1 m makes the corridor's posterior the odometry's
        (``tests/test_scan_match.py``), but on the real logs' rows it loses fr079's last loop
        more often (docs/real-logs.md, Alternatives not used).
    max_neighbour_gap_m : float
        A reference point's local line is used only when its neighbours are within this of
        each other (m; no line across a depth jump).
    max_line_thickness : float
        ... and when they are thin: the smaller eigenvalue of their scatter is at most this
        fraction of the larger (a straight piece of wall, not a corner).
    max_correspondence_m : float
        A point pairs with the nearest reference point within this (m) in the first
        iterations.
    inlier_m : float
        ... and within this (m) in the last ones; the points within it count as the overlap.
    rotation_window_rad, rotation_step_rad : float
        Starts of the search: the odometry's rotation and rotations of it by multiples of
        the step up to the window (rad).
    coarse_iterations, max_iterations : int
        Iterations from each start; iterations of the refinement of the best start.
    min_overlap : float
        A match is used only when at least this fraction of the current scan's points that
        the reference scan could see (:func:`visible_points`: within its field of view and
        range, at the match) lie within ``inlier_m`` of a reference line.
    slip_probability : float
        Prior probability that a step's odometry heading is a slip (0: the odometry's
        Gaussian alone).
    slip_sigma_rad : float
        Standard deviation of a slip's heading error (rad), added to the odometry's, with the
        translation the odometry integrated along it (:func:`slip_covariance`); the search's
        ``rotation_window_rad`` covers two of them.
    contradicted_spread : {"disagreement", "slip"}
        The heading spread of a step centred on a contradicted match
        (:attr:`ScanMatch.contradicted`): as far as the odometry's heading (the default,
        :func:`contradicted_covariance`), or the slip component's (``slip_sigma_rad``,
        :func:`slip_covariance`; ``docs/real-logs.md``, Opt-in settings).
    between_keyframes : bool
        Match every scan between two keyframes against the last keyframe, from its odometry
        since the keyframe (:func:`refine_scan`; the default): an accepted match is the scan's
        offset from its keyframe, with the match's covariance, in the result (the graph is
        unchanged); where the run's points scatter more than the noise model says
        (``summary.json`` ``range_noise``), the points' information in that covariance is
        divided by the ratio of the variances (:func:`scale_points_information`).  A
        refinement not accepted is followed by the search (:func:`match_scans`), and where
        the next keyframe's match finds a slip, the scans since the last keyframe are
        searched too.  False: such
        a scan is placed at its keyframe's pose composed with the odometry since (and the
        keyframes' correction shared along the stretch), for about 9 % less CPU time on
        Intel (``docs/benchmarks.md``).
    """

    RENAMED_KEYS: ClassVar[dict[str, str]] = {
        "normal_points": "replaced by normal_span_rad: the local line covers an angle of the "
        "scan, whatever its beam spacing",
    }

    enabled: bool = True
    model_sigma_m: float = 0.02
    normal_span_rad: float = math.radians(2.0)
    normal_length_m: float = 0.0
    max_neighbour_gap_m: float = 0.3
    max_line_thickness: float = 0.05
    max_correspondence_m: float = 0.5
    inlier_m: float = 0.1
    rotation_window_rad: float = 0.7
    rotation_step_rad: float = 0.175
    coarse_iterations: int = 6
    max_iterations: int = 30
    min_overlap: float = 0.5
    slip_probability: float = 0.01
    slip_sigma_rad: float = 0.35
    contradicted_spread: Literal["disagreement", "slip"] = "disagreement"
    between_keyframes: bool = True

    def __post_init__(self) -> None:
        nonneg("model_sigma_m", self.model_sigma_m)
        positive("normal_span_rad", self.normal_span_rad)
        nonneg("normal_length_m", self.normal_length_m)
        positive("max_neighbour_gap_m", self.max_neighbour_gap_m)
        require(0.0 < self.max_line_thickness < 1.0, "max_line_thickness must be in (0, 1)")
        positive("max_correspondence_m", self.max_correspondence_m)
        positive("inlier_m", self.inlier_m)
        nonneg("rotation_window_rad", self.rotation_window_rad)
        positive("rotation_step_rad", self.rotation_step_rad)
        require(self.coarse_iterations >= 1, "coarse_iterations must be >= 1")
        require(self.max_iterations >= 1, "max_iterations must be >= 1")
        require(0.0 <= self.min_overlap <= 1.0, "min_overlap must be in [0, 1]")
        require(0.0 <= self.slip_probability < 1.0, "slip_probability must be in [0, 1)")
        positive("slip_sigma_rad", self.slip_sigma_rad)
        require(
            self.contradicted_spread in ("slip", "disagreement"),
            f"contradicted_spread must be slip or disagreement: {self.contradicted_spread!r}",
        )


@dataclass(frozen=True, eq=False)
class ScanPoints:
    """The valid points of one scan, in beam order, with their Eq. 8 covariances.

    Attributes
    ----------
    xy : ndarray, shape (n, 2)
        Points in the laser frame (m).
    q11, q12, q22 : ndarray, shape (n,)
        Entries of each point's covariance (m², laser frame).
    normals : ndarray, shape (n, 2)
        Unit normal of each point's local line (zero where there is none).
    has_normal : ndarray of bool, shape (n,)
        Whether the point has a local line (it can then be a reference for another scan).
    segment : ndarray of int, shape (n,)
        The piece of wall each point with a local line lies on: runs of consecutive such
        points without a depth jump share one (−1 for the others).  A wall's model error is
        shared by its points.
    noise_ratio : float
        The scan's noise against Eq. 8, in variance: the median over the windows of
        ``2h + 1`` consecutive points without a depth jump (``max_neighbour_gap_m``) of the
        smaller eigenvalue of their scatter over their mean Eq. 8 variance along the window's
        normal, divided by the median of χ² with ``2h − 1`` degrees of freedom.  About 1
        where the points scatter about straight walls as Eq. 8 says, about ``k²`` for
        Gaussian range noise ``k`` times ``sigma_range_m`` (``tests/test_range_noise.py``);
        more for rough or cluttered walls.  Ranges written in steps much coarser than their
        noise read as flat runs and steps rather than scatter, which the median can miss.
        NaN without local lines (``with_normals`` False) or without such a window.
    view : tuple of float, optional
        ``(first_bearing_rad, span_rad, max_range_m)``: what these points could see, for
        :func:`visible_points`; None (a single scan's points in beam order): from the
        points themselves.  Points merged from several scans (a local map) state the view of
        the scan whose frame they are in.
    """

    xy: FloatArray
    q11: FloatArray
    q12: FloatArray
    q22: FloatArray
    normals: FloatArray
    has_normal: NDArray[np.bool_]
    segment: NDArray[np.int64]
    noise_ratio: float = math.nan
    view: tuple[float, float, float] | None = None

    def __len__(self) -> int:
        return int(self.xy.shape[0])


def normal_half_window(bearings: FloatArray, config: ScanMatchConfig) -> int:
    """``h``: a local line is fitted to ``2h + 1`` consecutive points (``normal_span_rad``).

    The beam step is the median step between consecutive bearings.
    """
    b = np.asarray(bearings, dtype=float)
    steps = np.abs(np.diff(b))
    steps = steps[steps > 0.0]
    if steps.size == 0:
        return 1
    return max(1, round(config.normal_span_rad / (2.0 * float(np.median(steps)))))


def _local_lines(
    xy: FloatArray,
    q11: FloatArray,
    q12: FloatArray,
    q22: FloatArray,
    h: int,
    config: ScanMatchConfig,
) -> tuple[FloatArray, NDArray[np.bool_], float]:
    """Normals of each point's local line (``2h + 1`` consecutive points centred on it).

    Also the scan's noise against Eq. 8 (:attr:`ScanPoints.noise_ratio`; NaN without a window
    of ``2h + 1`` points free of depth jumps).
    """
    n = xy.shape[0]
    normals = np.zeros((n, 2))
    ok = np.zeros(n, dtype=bool)
    k = 2 * h + 1
    if n < k:
        return normals, ok, math.nan
    # windows of k consecutive points, centred on points h .. n-h-1
    idx = np.arange(n - k + 1)[:, None] + np.arange(k)[None, :]
    W = xy[idx]  # (m, k, 2)
    gaps = np.linalg.norm(np.diff(W, axis=1), axis=2).max(axis=1)
    c = W - W.mean(axis=1, keepdims=True)
    sxx = np.einsum("mk,mk->m", c[..., 0], c[..., 0])
    sxy = np.einsum("mk,mk->m", c[..., 0], c[..., 1])
    syy = np.einsum("mk,mk->m", c[..., 1], c[..., 1])
    # eigen-decomposition of [[sxx, sxy], [sxy, syy]]
    tr = sxx + syy
    disc = np.sqrt(np.maximum((sxx - syy) ** 2 + 4.0 * sxy**2, 0.0))
    lam_max = 0.5 * (tr + disc)
    lam_min = 0.5 * (tr - disc)
    # the line's direction is the eigenvector of the larger eigenvalue: angle φ with
    # tan 2φ = 2 sxy / (sxx − syy); the normal is perpendicular to it
    phi = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)
    good = (gaps <= config.max_neighbour_gap_m) & (lam_max > 0.0)
    good &= lam_min <= config.max_line_thickness * np.where(lam_max > 0.0, lam_max, 1.0)
    centre = np.arange(h, n - h)
    nx, ny = -np.sin(phi), np.cos(phi)
    normals[centre, 0] = nx
    normals[centre, 1] = ny
    ok[centre] = good
    normals[~ok] = 0.0
    straight = (gaps <= config.max_neighbour_gap_m) & (lam_max > 0.0)
    any_straight = bool(straight.any())
    noise_ratio = math.nan
    if any_straight:
        # the scan's own noise against Eq. 8's: the short lines' spread about themselves
        # (every window without a depth jump, thin or not; the median, robust to corners and
        # clutter) against the median of χ² with k − 2 degrees of freedom
        with interrupts.deferred():  # compiled code (the first call loads it)
            noise_ratio = _median_spread_ratio(lam_min, nx, ny, q11, q12, q22, straight)
        noise_ratio /= _chi2_median(k - 2)
    if config.normal_length_m > 0.0 and any_straight:
        noise_scale = max(1.0, noise_ratio)
        _extend_lines(
            xy,
            q11,
            q12,
            q22,
            h,
            ok,
            normals,
            noise_scale,
            0.5 * config.normal_length_m,
            config.max_neighbour_gap_m,
            config.max_line_thickness,
        )
    return normals, ok, noise_ratio


@njit(cache=True, nogil=True)
def _median_spread_ratio(
    lam_min: FloatArray,
    nx: FloatArray,
    ny: FloatArray,
    q11: FloatArray,
    q12: FloatArray,
    q22: FloatArray,
    use: NDArray[np.bool_],
) -> float:
    """Median over the windows ``use`` of ``lam_min`` over the mean Eq. 8 variance along ``n``.

    Window ``i`` holds points ``i .. i + k − 1`` (``k = q11.size − lam_min.size + 1``).
    """
    m = lam_min.shape[0]
    k = q11.shape[0] - m + 1
    ratio = np.empty(m)
    count = 0
    for i in range(m):
        if not use[i]:
            continue
        a = 0.0
        b = 0.0
        c = 0.0
        for j in range(i, i + k):
            a += q11[j]
            b += q12[j]
            c += q22[j]
        var = (nx[i] * nx[i] * a + 2.0 * nx[i] * ny[i] * b + ny[i] * ny[i] * c) / k
        ratio[count] = lam_min[i] / max(var, 1e-12)
        count += 1
    return float(np.median(ratio[:count]))


def _chi2_median(dof: int) -> float:
    """Median of χ² with ``dof`` degrees of freedom.

    Wilson-Hilferty, within 1 % from 3 degrees of freedom on; exact values below.
    """
    if dof == 1:
        return 0.4549
    if dof == 2:
        return 1.3863
    c = 2.0 / (9.0 * dof)
    return dof * (1.0 - c) ** 3


@njit(cache=True, nogil=True)
def _chi2_99(dof: int) -> float:
    """99 % quantile of χ² with ``dof`` degrees of freedom.

    Wilson-Hilferty, within 1 % from 3 degrees of freedom on; exact values below.
    """
    if dof <= 0:
        return math.inf
    if dof == 1:
        return 6.635
    if dof == 2:
        return 9.210
    c = 2.0 / (9.0 * dof)
    return dof * (1.0 - c + 2.3263 * math.sqrt(c)) ** 3


@njit(cache=True, nogil=True)
def _window_scatter(
    xy: FloatArray,
    q11: FloatArray,
    q12: FloatArray,
    q22: FloatArray,
    lo: int,
    hi: int,
    cx: float,
    cy: float,
    nx: float,
    ny: float,
) -> tuple[float, float, float, float, float]:
    """Mean and scatter ``(mx, my, sxx, sxy, syy)`` of the points ``lo..hi`` about ``(cx, cy)``.

    Each point weighted by the inverse of its Eq. 8 variance along the normal ``(nx, ny)``;
    unweighted when the normal is zero.
    """
    weighted = nx != 0.0 or ny != 0.0
    sw = 0.0
    mx = 0.0
    my = 0.0
    for j in range(lo, hi + 1):
        w = 1.0
        if weighted:
            w = 1.0 / max(nx * nx * q11[j] + 2.0 * nx * ny * q12[j] + ny * ny * q22[j], 1e-12)
        sw += w
        mx += w * (xy[j, 0] - cx)
        my += w * (xy[j, 1] - cy)
    mx /= sw
    my /= sw
    sxx = 0.0
    sxy = 0.0
    syy = 0.0
    for j in range(lo, hi + 1):
        w = 1.0
        if weighted:
            w = 1.0 / max(nx * nx * q11[j] + 2.0 * nx * ny * q12[j] + ny * ny * q22[j], 1e-12)
        dx = xy[j, 0] - cx - mx
        dy = xy[j, 1] - cy - my
        sxx += w * dx * dx
        sxy += w * dx * dy
        syy += w * dy * dy
    return mx, my, sxx, sxy, syy


@njit(cache=True, nogil=True)
def _extend_lines(
    xy: FloatArray,
    q11: FloatArray,
    q12: FloatArray,
    q22: FloatArray,
    h: int,
    ok: NDArray[np.bool_],
    normals: FloatArray,
    noise_scale: float,
    reach_m: float,
    max_gap_m: float,
    max_thickness: float,
) -> None:
    """Refit the local line of every point with one over the points within ``reach_m`` of it.

    The window grows from the point's ``2h + 1`` on each side while the next point is within
    ``reach_m`` of the centre and ``max_gap_m`` of its neighbour; the normal of the longer
    window replaces the short one's where that window is thin (smaller eigenvalue of its
    scatter at most ``max_thickness`` times the larger) and its points lie on its line as
    their own noise allows (the sum of their squared distances to it over their Eq. 8
    variances along its normal, times ``noise_scale``, within the 99 % quantile of χ² with
    ``k − 2`` degrees of freedom; a point counts at most 9, three standard deviations), in
    place.  Where it does not (a corner, a bend, a rough or cluttered wall
    within reach), the reach is halved until it does, or until the window is the short one.
    """
    n = xy.shape[0]
    gap2 = max_gap_m * max_gap_m
    for i in range(n):
        if not ok[i]:
            continue
        cx, cy = xy[i, 0], xy[i, 1]
        reach = reach_m
        while True:
            reach2 = reach * reach
            lo, hi = i - h, i + h
            while lo > 0:
                ex, ey = xy[lo - 1, 0] - cx, xy[lo - 1, 1] - cy
                gx, gy = xy[lo - 1, 0] - xy[lo, 0], xy[lo - 1, 1] - xy[lo, 1]
                if ex * ex + ey * ey > reach2 or gx * gx + gy * gy > gap2:
                    break
                lo -= 1
            while hi < n - 1:
                ex, ey = xy[hi + 1, 0] - cx, xy[hi + 1, 1] - cy
                gx, gy = xy[hi + 1, 0] - xy[hi, 0], xy[hi + 1, 1] - xy[hi, 1]
                if ex * ex + ey * ey > reach2 or gx * gx + gy * gy > gap2:
                    break
                hi += 1
            if lo == i - h and hi == i + h:
                break  # no longer than the short line: it stays
            k = hi - lo + 1
            mx, my, sxx, sxy, syy = _window_scatter(xy, q11, q12, q22, lo, hi, cx, cy, 0.0, 0.0)
            disc = math.sqrt(max((sxx - syy) ** 2 + 4.0 * sxy * sxy, 0.0))
            lam_max = 0.5 * (sxx + syy + disc)
            lam_min = 0.5 * (sxx + syy - disc)
            if lam_max > 0.0 and lam_min <= max_thickness * lam_max:
                phi = 0.5 * math.atan2(2.0 * sxy, sxx - syy)
                nx, ny = -math.sin(phi), math.cos(phi)
                # refitted with each point weighted by its Eq. 8 variance along the normal
                # (near and far points of one wall are not equally precise along it), then
                # the points' spread about the line against that noise
                for _ in range(2):
                    mx, my, sxx, sxy, syy = _window_scatter(
                        xy, q11, q12, q22, lo, hi, cx, cy, nx, ny
                    )
                    phi = 0.5 * math.atan2(2.0 * sxy, sxx - syy)
                    nx, ny = -math.sin(phi), math.cos(phi)
                chi2 = 0.0
                for j in range(lo, hi + 1):
                    r = nx * (xy[j, 0] - cx - mx) + ny * (xy[j, 1] - cy - my)
                    var = nx * nx * q11[j] + 2.0 * nx * ny * q12[j] + ny * ny * q22[j]
                    # one stray point weighs as 3 σ at most: a bend or a corner is many
                    chi2 += min(r * r / max(noise_scale * var, 1e-12), 9.0)
                if chi2 <= _chi2_99(k - 2):
                    normals[i, 0] = nx
                    normals[i, 1] = ny
                    break
            reach *= 0.5  # a corner or a bend within reach: a shorter line


def scan_points(
    ranges: FloatArray,
    bearings: FloatArray,
    max_range_m: float,
    noise: SensorNoiseConfig,
    config: ScanMatchConfig,
    with_normals: bool = True,
) -> ScanPoints:
    """The valid readings of a scan as :class:`ScanPoints` (laser frame).

    Readings that are not finite, not positive, or at or beyond ``max_range_m`` (no return)
    are left out.  Without ``with_normals`` no point gets a local line (``has_normal`` all
    False, ``segment`` all −1): enough for a scan that is only ever matched, never a reference.
    """
    d = np.asarray(ranges, dtype=float)
    b = np.asarray(bearings, dtype=float)
    valid = np.isfinite(d) & (d > 0.0) & (d < max_range_m)
    d_valid, b_valid = d[valid], b[valid]
    xy = np.stack([d_valid * np.cos(b_valid), d_valid * np.sin(b_valid)], axis=-1)
    q11, q12, q22 = point_covariance_entries(d_valid, b_valid, noise)
    if not with_normals:
        n = xy.shape[0]
        return ScanPoints(
            xy, q11, q12, q22, np.zeros((n, 2)), np.zeros(n, dtype=bool), np.full(n, -1)
        )
    h = normal_half_window(b, config)
    normals, ok, noise_ratio = _local_lines(xy, q11, q12, q22, h, config)
    return ScanPoints(xy, q11, q12, q22, normals, ok, _segments(xy, ok, config), noise_ratio)


def _segments(xy: FloatArray, ok: NDArray[np.bool_], config: ScanMatchConfig) -> NDArray[np.int64]:
    """Segment id of each point with a local line (module docstring of :class:`ScanPoints`)."""
    n = xy.shape[0]
    seg = np.full(n, -1, dtype=np.int64)
    if n == 0:
        return seg
    gap = np.r_[np.inf, np.linalg.norm(np.diff(xy, axis=0), axis=1)]
    # a new segment starts at a point with a line whose predecessor has none or is far
    prev_ok = np.r_[False, ok[:-1]]
    start = ok & (~prev_ok | (gap > config.max_neighbour_gap_m))
    ids = np.cumsum(start) - 1
    seg[ok] = ids[ok]
    return seg


@dataclass(frozen=True, eq=False)
class ScanMatch:
    """Outcome of :func:`match_scans`.

    Attributes
    ----------
    delta : ndarray, shape (3,)
        Pose of the current scan's laser in the reference scan's laser frame ``(x, y, θ)``.
    cov : ndarray, shape (3, 3)
        Its covariance.
    overlap : float
        Fraction of the current scan's points visible from the reference
        (:func:`visible_points`) within ``inlier_m`` of a reference line.
    inliers : int
        Their number.
    start_offset_rad : float
        The rotation added to the odometry at the start the match was refined from.
    accepted : bool
        ``overlap >= min_overlap`` and a finite, positive-definite covariance.
    slip : bool
        Accepted, and the odometry's heading slipped (the slip component of the prior is the
        more probable at the match; :class:`ScanMatchConfig` ``slip_probability``): ``cov``
        then holds the slip component (the rotation spread, the translation moved with it) and
        the points.
    contradicted : bool
        Not accepted, yet the slip component is the more probable at the match: the points
        contradict the odometry's heading, with too little overlap to be trusted as a
        measurement.  The pipeline then centres the step on ``delta`` with
        :func:`contradicted_covariance`: spread along the slip as far as the odometry's
        heading (or, with ``contradicted_spread = "slip"``, the slip component's covariance).
    """

    delta: FloatArray
    cov: FloatArray
    overlap: float
    inliers: int
    start_offset_rad: float
    accepted: bool
    slip: bool = False
    contradicted: bool = False


jit = njit(cache=True, error_model="numpy", nogil=True)


_Grid = tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]
"""``(keys, order, columns)`` of :func:`_grid`."""


@jit
def _grid(p: FloatArray, cell: float) -> _Grid:
    """The points ``p`` by cell (cells of side ``cell``): ``(keys, order, columns)``.

    ``keys`` are the cells' keys sorted (a column ``cx`` is the block of keys
    ``cx·_SPAN + cy``), ``order`` the points in that order; ``columns[0]`` is the first column
    and ``columns[1 + r] : columns[2 + r]`` the keys of column ``columns[0] + r``.
    """
    m = p.shape[0]
    keys = np.empty(m, dtype=np.int64)
    for i in range(m):
        cx = np.int64(np.floor(p[i, 0] / cell)) + _OFFSET
        cy = np.int64(np.floor(p[i, 1] / cell)) + _OFFSET
        keys[i] = cx * _SPAN + cy
    order = np.argsort(keys, kind="mergesort")
    keys = keys[order]
    if m == 0:
        return keys, order, np.zeros(2, dtype=np.int64)
    first = keys[0] // _SPAN
    n_columns = keys[m - 1] // _SPAN - first + 1
    columns = np.empty(n_columns + 2, dtype=np.int64)
    columns[0] = first
    k = 0
    for r in range(n_columns + 1):
        while k < m and keys[k] // _SPAN < first + r:
            k += 1
        columns[1 + r] = k
    return keys, order, columns


@jit
def _nearest(
    qx: float,
    qy: float,
    p: FloatArray,
    keys: NDArray[np.int64],
    order: NDArray[np.int64],
    columns: NDArray[np.int64],
    cell: float,
    d_max: float,
) -> int:
    """Index of the point of ``p`` nearest to ``(qx, qy)`` within ``d_max`` (≤ ``cell``), or −1.

    Of points at equal distance, the last in the grid's order (``keys``, ``order``, ``columns``:
    :func:`_grid`).
    """
    cx = np.int64(np.floor(qx / cell)) + _OFFSET
    cy = np.int64(np.floor(qy / cell)) + _OFFSET
    best = -1
    best_d2 = d_max * d_max
    n_columns = columns.shape[0] - 2
    for dx in range(-1, 2):
        # the three cells (cx + dx, cy − 1 .. cy + 1) have consecutive keys in their column
        r = cx + dx - columns[0]
        if r < 0 or r >= n_columns:
            continue
        lo = columns[1 + r]
        hi = columns[2 + r]
        base = (cx + dx) * _SPAN
        target = base + cy - 1
        while lo < hi:  # the first key of the column at or above the lowest of the cells
            mid = (lo + hi) >> 1
            if keys[mid] < target:
                lo = mid + 1
            else:
                hi = mid
        last = base + cy + 1
        while lo < keys.size and keys[lo] <= last:
            j = order[lo]
            ex = p[j, 0] - qx
            ey = p[j, 1] - qy
            d2 = ex * ex + ey * ey
            if d2 <= best_d2:
                best_d2 = d2
                best = j
            lo += 1
    return best


@jit
def _normal_equations(
    x: FloatArray,
    p: FloatArray,
    n: FloatArray,
    var_ref: FloatArray,
    keys: NDArray[np.int64],
    order: NDArray[np.int64],
    columns: NDArray[np.int64],
    cell: float,
    d_max: float,
    q: FloatArray,
    q11: FloatArray,
    q12: FloatArray,
    q22: FloatArray,
    inlier_m: float,
    with_cost: bool = True,
) -> tuple[FloatArray, FloatArray, int, int, float, float]:
    """``H = Σ w JᵀJ``, ``g = Σ w J e`` at ``x`` (Cauchy weights over each residual's variance).

    Also returns the number of pairs within ``d_max``, of residuals within ``inlier_m``,
    ``Σ w e²`` and the robust cost ``Σ ½ log(1 + e²/σ²)`` of the pairs (all four 0 without
    ``with_cost``: a Gauss-Newton step needs only ``H`` and ``g``).
    """
    c = np.cos(x[2])
    s = np.sin(x[2])
    H = np.zeros((3, 3))
    g = np.zeros(3)
    pairs = 0
    inliers = 0
    wee = 0.0
    cost = 0.0
    for i in range(q.shape[0]):
        qx = c * q[i, 0] - s * q[i, 1] + x[0]
        qy = s * q[i, 0] + c * q[i, 1] + x[1]
        j = _nearest(qx, qy, p, keys, order, columns, cell, d_max)
        if j < 0:
            continue
        nx = n[j, 0]
        ny = n[j, 1]
        e = nx * (qx - p[j, 0]) + ny * (qy - p[j, 1])
        # the current point's covariance along the normal (normal rotated into its frame)
        lx = c * nx + s * ny
        ly = -s * nx + c * ny
        var = var_ref[j] + lx * lx * q11[i] + 2.0 * lx * ly * q12[i] + ly * ly * q22[i]
        w = 1.0 / (var + e * e)  # Cauchy weight over the variance: 1 / (σ² (1 + e²/σ²))
        dqx = -s * q[i, 0] - c * q[i, 1]
        dqy = c * q[i, 0] - s * q[i, 1]
        J0 = nx
        J1 = ny
        J2 = nx * dqx + ny * dqy
        H[0, 0] += w * J0 * J0
        H[0, 1] += w * J0 * J1
        H[0, 2] += w * J0 * J2
        H[1, 1] += w * J1 * J1
        H[1, 2] += w * J1 * J2
        H[2, 2] += w * J2 * J2
        g[0] += w * J0 * e
        g[1] += w * J1 * e
        g[2] += w * J2 * e
        if with_cost:
            wee += w * e * e
            cost += 0.5 * np.log1p(e * e / var)
            pairs += 1
            if abs(e) <= inlier_m:
                inliers += 1
    H[1, 0] = H[0, 1]
    H[2, 0] = H[0, 2]
    H[2, 1] = H[1, 2]
    return H, g, pairs, inliers, wee, cost


@jit
def _gauss_newton(
    x0: FloatArray,
    iterations: int,
    x_prior: FloatArray,
    info_prior: FloatArray,
    p: FloatArray,
    n: FloatArray,
    var_ref: FloatArray,
    keys: NDArray[np.int64],
    order: NDArray[np.int64],
    columns: NDArray[np.int64],
    cell: float,
    d_max: float,
    q: FloatArray,
    q11: FloatArray,
    q12: FloatArray,
    q22: FloatArray,
) -> FloatArray:
    """Gauss-Newton from ``x0`` with the prior ``(x_prior, info_prior)``.

    At most ``iterations``; stops when a step is below 1e-7 (m, rad).
    """
    x = x0.copy()
    for _ in range(iterations):
        H, g, _, _, _, _ = _normal_equations(
            x, p, n, var_ref, keys, order, columns, cell, d_max, q, q11, q12, q22, d_max, False
        )
        r = x - x_prior
        r[2] = np.arctan2(np.sin(r[2]), np.cos(r[2]))
        H = H + info_prior
        g = g + info_prior @ r
        if np.linalg.det(H) <= 0.0:
            break
        dx = -np.linalg.solve(H, g)
        x = x + dx
        if np.max(np.abs(dx)) < 1e-7:
            break
    return x


@jit
def _gauss_newton_starts(
    x0: FloatArray,
    offsets: FloatArray,
    iterations: int,
    x_prior: FloatArray,
    info_prior: FloatArray,
    p: FloatArray,
    n: FloatArray,
    var_ref: FloatArray,
    grid: _Grid,
    d_max: float,
    inlier_grid: _Grid,
    inlier_m: float,
    q: FloatArray,
    q11: FloatArray,
    q12: FloatArray,
    q22: FloatArray,
) -> tuple[FloatArray, NDArray[np.int64]]:
    """:func:`_gauss_newton` from ``x0`` rotated by each of ``offsets``, and the inliers.

    Pairs within ``d_max`` (``grid`` of that cell); the inliers (residuals within
    ``inlier_m``, ``inlier_grid``) counted at each solution.
    """
    xs = np.empty((offsets.shape[0], 3))
    inliers = np.empty(offsets.shape[0], dtype=np.int64)
    keys, order, columns = grid
    ikeys, iorder, icolumns = inlier_grid
    for k in range(offsets.shape[0]):
        start = np.empty(3)  # x0 + (0, 0, offset), as numpy adds them
        start[0] = x0[0] + 0.0
        start[1] = x0[1] + 0.0
        start[2] = x0[2] + offsets[k]
        x = _gauss_newton(
            start, iterations, x_prior, info_prior, p, n, var_ref, keys, order, columns, d_max,
            d_max, q, q11, q12, q22,
        )  # fmt: skip
        xs[k] = x
        inliers[k] = _normal_equations(
            x, p, n, var_ref, ikeys, iorder, icolumns, inlier_m, inlier_m, q, q11, q12, q22,
            inlier_m,
        )[3]  # fmt: skip
    return xs, inliers


def _cauchy_moments() -> tuple[float, float]:
    """``(E[ψ'], E[ψ²])`` of the Cauchy score ``ψ(r) = r/(1 + r²)`` for ``r ~ N(0, 1)``.

    ``ψ'(r) = (1 − r²)/(1 + r²)²``; Gauss-Hermite quadrature (probabilists', 200 nodes: to
    about 1e-10).
    """
    z, w = np.polynomial.hermite_e.hermegauss(200)
    w = w / math.sqrt(2.0 * math.pi)
    d = 1.0 + z * z
    return float(np.sum(w * (1.0 - z * z) / d**2)), float(np.sum(w * z * z / d**2))


CAUCHY_DPSI, CAUCHY_PSI2 = _cauchy_moments()
"""``E[ψ']`` and ``E[ψ²]`` of the Cauchy score for standard normal residuals (the sandwich)."""


@jit
def _sandwich(
    x: FloatArray,
    p: FloatArray,
    n: FloatArray,
    var_ref: FloatArray,
    keys: NDArray[np.int64],
    order: NDArray[np.int64],
    columns: NDArray[np.int64],
    d_max: float,
    q: FloatArray,
    q11: FloatArray,
    q12: FloatArray,
    q22: FloatArray,
    seg: NDArray[np.int64],
    n_seg: int,
    var_model: float,
    e_dpsi: float,
    e_psi2: float,
) -> tuple[FloatArray, FloatArray, int, int, float]:
    """``A``, ``B`` of the sandwich ``A⁻¹ B A⁻¹``, pairs, inliers and ``Σ w e²`` at ``x``.

    The Cauchy estimator's, in expectation under the noise model (each residual ``N(0, σ²)``,
    ``σ²`` its Eq. 8 variance plus ``σ_m²``): ``A = E[ψ'] Σ JᵀJ/σ²``;
    ``B = Σ (E[ψ²]/σ² − E[ψ']² σ_m²/σ⁴) JᵀJ + E[ψ']² σ_m² Σ_segments (Σ J/σ²)ᵀ(Σ J/σ²)``:
    each residual's own score variance, and the model error as one offset per reference
    segment, shared by its points' scores.
    """
    c = np.cos(x[2])
    s = np.sin(x[2])
    A = np.zeros((3, 3))
    B = np.zeros((3, 3))
    S = np.zeros((n_seg, 3))
    pairs = 0
    inliers = 0
    wee = 0.0
    J = np.zeros(3)
    for i in range(q.shape[0]):
        qx = c * q[i, 0] - s * q[i, 1] + x[0]
        qy = s * q[i, 0] + c * q[i, 1] + x[1]
        j = _nearest(qx, qy, p, keys, order, columns, d_max, d_max)
        if j < 0:
            continue
        nx = n[j, 0]
        ny = n[j, 1]
        e = nx * (qx - p[j, 0]) + ny * (qy - p[j, 1])
        lx = c * nx + s * ny
        ly = -s * nx + c * ny
        var = var_ref[j] + lx * lx * q11[i] + 2.0 * lx * ly * q12[i] + ly * ly * q22[i]
        J[0] = nx
        J[1] = ny
        J[2] = nx * (-s * q[i, 0] - c * q[i, 1]) + ny * (c * q[i, 0] - s * q[i, 1])
        a_i = e_dpsi / var
        b_i = e_psi2 / var - e_dpsi * e_dpsi * var_model / (var * var)
        for a in range(3):
            for b in range(3):
                A[a, b] += a_i * J[a] * J[b]
                B[a, b] += b_i * J[a] * J[b]
            S[seg[j], a] += J[a] / var
        wee += e * e / (var + e * e)
        pairs += 1
        if abs(e) <= d_max:
            inliers += 1
    k2 = e_dpsi * e_dpsi * var_model
    for k in range(n_seg):
        for a in range(3):
            for b in range(3):
                B[a, b] += k2 * S[k, a] * S[k, b]
    return A, B, pairs, inliers, wee


_OFFSET = np.int64(1 << 20)
_SPAN = np.int64(1 << 22)


class _Matcher:
    """Point-to-line Gauss-Newton of one current scan against one reference scan."""

    def __init__(
        self,
        ref: ScanPoints,
        cur: ScanPoints,
        config: ScanMatchConfig,
        x_prior: FloatArray,
        info_prior: FloatArray,
        prior_cost: Callable[[FloatArray], float],
    ) -> None:
        self.cfg = config
        self.x_prior = np.asarray(x_prior, dtype=float)
        self.info_prior = np.asarray(info_prior, dtype=float)
        """The Gauss-Newton iterations' prior information (about ``x_prior``)."""
        self.prior_cost = prior_cost
        """The prior's negative log density in :meth:`objective`."""
        keep = np.flatnonzero(ref.has_normal)
        self.p = np.ascontiguousarray(ref.xy[keep])
        self.n = np.ascontiguousarray(ref.normals[keep])
        # the reference point's variance along its normal (Eq. 8) plus the model error
        n = self.n
        self.var_ref = (
            n[:, 0] ** 2 * ref.q11[keep] + 2 * n[:, 0] * n[:, 1] * ref.q12[keep]
            + n[:, 1] ** 2 * ref.q22[keep] + config.model_sigma_m**2
        )  # fmt: skip
        self.seg = np.ascontiguousarray(ref.segment[keep])
        self.n_seg = int(self.seg.max(initial=-1)) + 1
        self.q = np.ascontiguousarray(cur.xy)
        self.cq = (cur.q11, cur.q12, cur.q22)
        self._grids: dict[float, _Grid] = {}

    def _grid(self, d_max: float) -> _Grid:
        if d_max not in self._grids:
            self._grids[d_max] = _grid(self.p, d_max)
        return self._grids[d_max]

    def normal_equations(
        self, x: FloatArray, d_max: float
    ) -> tuple[FloatArray, FloatArray, int, int, float, float]:
        """``(H, g, pairs, inliers, Σ w e², cost)`` at ``x`` for the pairs within ``d_max``."""
        keys, order, columns = self._grid(d_max)
        return _normal_equations(
            np.asarray(x, dtype=float), self.p, self.n, self.var_ref, keys, order, columns, d_max,
            d_max, self.q, *self.cq, self.cfg.inlier_m,
        )  # fmt: skip

    def solve(self, x0: FloatArray, iterations: int, d_max: float) -> FloatArray:
        """Gauss-Newton with Cauchy weights from ``x0`` (pairs within ``d_max``)."""
        if self.p.shape[0] < 3:
            return np.array(x0, dtype=float)
        keys, order, columns = self._grid(d_max)
        return _gauss_newton(
            np.array(x0, dtype=float), iterations, self.x_prior, self.info_prior, self.p, self.n,
            self.var_ref, keys, order, columns, d_max, d_max, self.q, *self.cq,
        )  # fmt: skip

    def solve_starts(
        self, x0: FloatArray, offsets: FloatArray, iterations: int, d_max: float
    ) -> tuple[FloatArray, NDArray[np.int64]]:
        """:meth:`solve` from ``x0`` rotated by each offset, and :meth:`inliers` at each.

        One compiled call; returns ``(xs (K, 3), inliers (K,))``.
        """
        if self.p.shape[0] < 3:  # as solve and inliers: the starts, no inliers
            xs = np.array(x0, dtype=float) + np.outer(offsets, [0.0, 0.0, 1.0])
            return xs, np.zeros(offsets.shape[0], dtype=np.int64)
        return _gauss_newton_starts(
            np.array(x0, dtype=float), offsets, iterations, self.x_prior, self.info_prior,
            self.p, self.n, self.var_ref, self._grid(d_max), d_max,
            self._grid(self.cfg.inlier_m), self.cfg.inlier_m, self.q, *self.cq,
        )  # fmt: skip

    def objective(self, x: FloatArray, kappa: float = 1.0) -> float:
        """The negative log-posterior at ``x`` (up to a constant).

        ``Σ ½ log(1 + e²/σ²)`` over the pairs within ``inlier_m``, ``½ log(1 + inlier_m²/σ_m²)``
        for each unpaired point (an outlier's cost), divided by ``kappa`` (the points are not
        independent: :meth:`overconfidence`), plus the prior's cost.
        """
        cfg = self.cfg
        out = 0.5 * math.log1p(cfg.inlier_m**2 / max(cfg.model_sigma_m**2, 1e-12))
        if self.p.shape[0] < 3:
            data = self.q.shape[0] * out
        else:
            _, _, pairs, _, _, cost = self.normal_equations(x, cfg.inlier_m)
            data = cost + (self.q.shape[0] - pairs) * out
        return float(data / kappa + self.prior_cost(np.asarray(x, dtype=float)))

    def overconfidence(self, x: FloatArray) -> float:
        """How much the summed cost overstates the points' evidence at ``x`` (at least 1).

        The cost treats every point as independent; its curvature ``H`` is the information it
        claims, while the sandwich covariance ``C`` (:meth:`covariance`) is the one the
        points carry.  ``κ = tr(H C) / 3``, the mean of the eigenvalues of ``H C``, scales
        cost differences to log-likelihood ratios (the magnitude adjustment of a composite
        likelihood, Chandler & Bate 2007).
        """
        C, _ = self.covariance(x)
        if not np.all(np.isfinite(C)):
            return 1.0
        H = self.normal_equations(x, self.cfg.inlier_m)[0]
        return max(float(np.trace(H @ C)) / 3.0, 1.0)

    def inliers(self, x: FloatArray) -> int:
        """Current points within ``inlier_m`` of a reference line at ``x``."""
        if self.p.shape[0] < 3:
            return 0
        return int(self.normal_equations(x, self.cfg.inlier_m)[3])

    def covariance(self, x: FloatArray) -> tuple[FloatArray, int]:
        """Covariance of the match at ``x`` (the points' part) and the number of inliers.

        The Cauchy M-estimator's sandwich ``A⁻¹ B A⁻¹`` over the pairs within ``inlier_m``, in
        expectation under the noise model (:func:`_sandwich`): each residual's Eq. 8 variance
        is its own, while the model error (``model_sigma_m``) is one offset shared by the
        points on one piece of reference wall (:attr:`ScanPoints.segment`), so that many
        points on one wall weigh as one wall.  Times the variance factor of the robust
        residuals when it exceeds 1.
        """
        if self.p.shape[0] < 3:
            return np.full((3, 3), np.nan), 0
        keys, order, columns = self._grid(self.cfg.inlier_m)
        A, B, pairs, inl, wee = _sandwich(
            np.asarray(x, dtype=float), self.p, self.n, self.var_ref, keys, order, columns,
            self.cfg.inlier_m, self.q, *self.cq, self.seg, self.n_seg,
            self.cfg.model_sigma_m**2, CAUCHY_DPSI, CAUCHY_PSI2,
        )  # fmt: skip
        if pairs < 3 or np.linalg.det(A) <= 0.0:
            return np.full((3, 3), np.nan), inl
        s2 = max(wee / max(pairs - 3, 1), 1.0)
        Ai = np.linalg.inv(A)
        cov = s2 * Ai @ B @ Ai
        return 0.5 * (cov + cov.T), inl


class _OdometryPrior:
    """The odometry step as the match's prior: its Gaussian, or a mixture with a heading slip.

    ``N(x0, Q)`` with probability ``1 − ε`` and ``N(x0, Q + σ_slip² v vᵀ)`` with probability
    ``ε`` (``slip_probability``, ``slip_sigma_rad``; ``v`` the slip's direction,
    :func:`slip_covariance`); ``ε = 0``: the Gaussian.
    """

    def __init__(self, x0: FloatArray, Q: FloatArray, config: ScanMatchConfig) -> None:
        self.x0 = x0
        self.slip_probability = eps = config.slip_probability
        self.cov = Q
        self.cov_slip = slip_covariance(Q, config, x0)
        self.info = _symmetric_inverse(Q)
        self.info_slip = _symmetric_inverse(self.cov_slip)
        self.info_search = self.info_slip if eps > 0.0 else self.info
        # log weights (mixture weight / √det) of the two components
        self._log_w = (
            math.log1p(-eps) - 0.5 * math.log(np.linalg.det(Q)),
            (math.log(eps) if eps > 0.0 else -math.inf)
            - 0.5 * math.log(np.linalg.det(self.cov_slip)),
        )

    def _components(self, x: FloatArray) -> tuple[float, float]:
        """Log density (up to a shared constant) of each component at ``x``."""
        r = np.asarray(x, dtype=float) - self.x0
        r[2] = math.remainder(float(r[2]), 2.0 * math.pi)
        return (
            self._log_w[0] - 0.5 * float(r @ self.info @ r),
            self._log_w[1] - 0.5 * float(r @ self.info_slip @ r),
        )

    def cost(self, x: FloatArray) -> float:
        """Negative log prior at ``x``, zero at ``x0`` without slips (``½ χ²`` of the Gaussian)."""
        l0, l1 = self._components(x)
        top = max(l0, l1)
        log_p = top + math.log(math.exp(l0 - top) + math.exp(l1 - top))
        return self._log_w[0] - log_p

    def is_slip(self, x: FloatArray) -> bool:
        """Whether the slip component is the more probable at ``x``."""
        l0, l1 = self._components(x)
        return l1 > l0


def slip_covariance(
    Q: FloatArray,
    config: ScanMatchConfig,
    delta: FloatArray | None = None,
    body: bool = False,
    sigma_rad: float | None = None,
) -> FloatArray:
    """The slip component's covariance: ``Q + σ_slip² v vᵀ`` (``slip_sigma_rad``).

    A slip is a heading error ``φ`` that the wheels accrue over the step, and the odometry
    integrates the step's translation ``t`` along that heading: to first order (a straight
    step, the error growing uniformly) the true step is the odometry's moved by
    ``φ v``, ``v = (−t_y/2, t_x/2, 1)`` in the step's start frame.

    Parameters
    ----------
    Q : ndarray, shape (3, 3)
        The odometry's covariance of the step.
    config : ScanMatchConfig
    delta : ndarray, shape (3,), optional
        The odometry's step ``(t_x, t_y, dθ)``; None: the heading only, ``v = (0, 0, 1)``.
    body : bool
        ``v`` in the step's end frame (the right tangent space of an odometry factor:
        its translation rotated by ``−dθ``) instead of the start frame (the match's
        coordinates).
    sigma_rad : float, optional
        The slip's spread ``σ_slip`` (rad) in place of ``config.slip_sigma_rad``.
    """
    cov = np.array(Q, dtype=np.float64)
    v = np.array([0.0, 0.0, 1.0])
    if delta is not None:
        t = np.asarray(delta, dtype=float)
        lever = 0.5 * np.array([-t[1], t[0]])
        if body:
            c, s = math.cos(float(t[2])), math.sin(float(t[2]))
            lever = np.array([c * lever[0] + s * lever[1], -s * lever[0] + c * lever[1]])
        v[:2] = lever
    sigma = config.slip_sigma_rad if sigma_rad is None else float(sigma_rad)
    cov += sigma**2 * np.outer(v, v)
    return cov


def contradicted_covariance(
    Q: FloatArray,
    config: ScanMatchConfig,
    delta_odometry: FloatArray,
    delta_match: FloatArray,
    body: bool = False,
) -> FloatArray:
    """Covariance of a step centred on a contradicted match (``contradicted_spread``).

    ``"disagreement"`` (the default): ``Q + φ² v vᵀ``.  ``"slip"``: the slip component's,
    ``Q + σ_slip² v vᵀ`` (:func:`slip_covariance`).  A contradicted match
    (:attr:`ScanMatch.contradicted`) turns the step by ``φ`` against the odometry, ``φ`` the
    heading of ``δ_match ⊖ δ_odometry``, with too little overlap to be trusted: either may be
    right.  Centred on the match, the step then gets the slip component's shape
    (:func:`slip_covariance`: the heading, with the translation the odometry integrated along
    it) with the spread ``|φ|``, the disagreement itself, in place of the prior
    ``slip_sigma_rad``: the odometry's heading lies about one standard deviation from the
    centre, so that the covariance holds both explanations along the slip, and no more.  A fixed
    spread wider than the disagreement leaves the heading there nearly free, and a line paired
    with a wall at right angles to it can then turn the trajectory at that step.

    Parameters
    ----------
    Q : ndarray, shape (3, 3)
        The odometry's covariance of the step.
    config : ScanMatchConfig
    delta_odometry, delta_match : ndarray, shape (3,)
        The odometry's step and the match's ``(t_x, t_y, dθ)``.
    body : bool
        As :func:`slip_covariance`.
    """
    if config.contradicted_spread == "slip":
        return slip_covariance(Q, config, delta_odometry, body=body)
    d = pose_log(pose_between(np.asarray(delta_odometry, float), np.asarray(delta_match, float)))
    return slip_covariance(Q, config, delta_odometry, body=body, sigma_rad=abs(float(d[2])))


def scale_points_information(
    posterior_cov: FloatArray, prior_cov: FloatArray, factor: float
) -> FloatArray:
    """A match's posterior covariance with the points' information divided by ``factor``.

    A match's posterior information is the points' plus the prior's (:func:`refine_scan`);
    where the points scatter ``√factor`` times as much as the noise model says (the run's
    :class:`~slam.line_slam.range_noise.RangeNoiseCheck`), their information is ``factor``
    times too large.  Returns ``(I_post − I_prior)/factor + I_prior)⁻¹``, ``(3, 3)``; a
    ``factor`` of 1 or less returns ``posterior_cov`` unchanged.
    """
    post = np.asarray(posterior_cov, dtype=np.float64)
    if not factor > 1.0:
        return post
    info_prior = _symmetric_inverse(np.asarray(prior_cov, dtype=np.float64))
    info_points = _symmetric_inverse(post) - info_prior
    return _symmetric_inverse(info_points / factor + info_prior)


def _symmetric_inverse(c: FloatArray) -> FloatArray:
    inv = np.linalg.inv(c)
    return np.asarray(0.5 * (inv + inv.T), dtype=np.float64)


def visible_points(reference: ScanPoints, current: ScanPoints, delta: FloatArray) -> int:
    """How many of ``current``'s points the reference scan could have seen, at ``delta``.

    A current point (moved into the reference laser's frame by ``delta``) is visible when its
    bearing lies within the reference's field of view (from its first to its last valid
    point, widened by half the median step between them on either side) and it is no
    farther than the reference's farthest valid point: the part of the current scan that the
    motion leaves in the reference's view.
    """
    if len(reference) == 0 or len(current) == 0:
        return 0
    first, span, max_range = reference.view if reference.view is not None else scan_view(reference)
    c, s = math.cos(float(delta[2])), math.sin(float(delta[2]))
    qx = c * current.xy[:, 0] - s * current.xy[:, 1] + float(delta[0])
    qy = s * current.xy[:, 0] + c * current.xy[:, 1] + float(delta[1])
    within_fov = np.mod(np.arctan2(qy, qx) - first, 2.0 * math.pi) <= span
    within_range = np.hypot(qx, qy) <= max_range
    return int(np.count_nonzero(within_fov & within_range))


def scan_view(points: ScanPoints) -> tuple[float, float, float]:
    """``(first_bearing_rad, span_rad, max_range_m)`` of one scan's points in beam order.

    The field of view runs from the first to the last valid point, widened by half the
    median step between them on either side (each beam covers half a step on either side);
    the range is the farthest valid point's.
    """
    ref = points.xy
    if ref.shape[0] == 0:
        return 0.0, 0.0, 0.0
    bearings = np.unwrap(np.arctan2(ref[:, 1], ref[:, 0]))
    first, span = float(bearings[0]), float(bearings[-1] - bearings[0])
    if span < 0.0:  # clockwise beam order
        first, span = float(bearings[-1]), -span
    steps = np.abs(np.diff(bearings))
    half_step = 0.5 * float(np.median(steps)) if steps.size else 0.0
    max_range = float(np.max(np.hypot(ref[:, 0], ref[:, 1])))
    return first - half_step, span + 2.0 * half_step, max_range


def _coarse_starts(
    matcher: _Matcher, x0: FloatArray, offsets: list[float], cfg: ScanMatchConfig
) -> list[tuple[int, float, FloatArray]]:
    """A few iterations from ``x0`` rotated by each offset: ``(inliers, offset, x)`` each."""
    xs, inliers = matcher.solve_starts(
        x0, np.asarray(offsets, dtype=float), cfg.coarse_iterations, cfg.max_correspondence_m
    )
    return [
        (int(n), off, x.copy()) for n, off, x in zip(inliers.tolist(), offsets, xs, strict=True)
    ]


def _refine(matcher: _Matcher, x: FloatArray, cfg: ScanMatchConfig) -> FloatArray:
    """A start refined: pairs within ``max_correspondence_m``, then within ``inlier_m``."""
    x = matcher.solve(x, cfg.max_iterations, cfg.max_correspondence_m)
    return matcher.solve(x, cfg.max_iterations, cfg.inlier_m)


def match_scans(
    reference: ScanPoints,
    current: ScanPoints,
    delta0: FloatArray,
    prior_cov: FloatArray,
    config: ScanMatchConfig,
) -> ScanMatch:
    """Register ``current`` against ``reference``, with the odometry as the prior.

    The estimate is the posterior mode of the relative pose: the points' robust likelihood
    (Cauchy) times the odometry's Gaussian ``N(delta0, prior_cov)`` (or, with
    ``slip_probability``, its mixture with a slip).  Where the points constrain the pose
    (nearly always the rotation) they decide, even against an odometry step tens of degrees
    off; where they do not (along a corridor) the odometry does.

    Parameters
    ----------
    reference, current : ScanPoints
        The previous keyframe's points and the current keyframe's.
    delta0 : ndarray, shape (3,)
        The odometry's pose of the current laser in the reference laser's frame.
    prior_cov : ndarray, shape (3, 3)
        Its covariance (the motion noise), positive definite.
    config : ScanMatchConfig

    Returns
    -------
    ScanMatch
        ``delta`` and ``cov`` are the posterior (odometry and points together).
    """
    cfg = config
    x0 = np.asarray(delta0, dtype=float)
    prior = _OdometryPrior(x0, np.asarray(prior_cov, dtype=float), cfg)
    # the search and the choice between starts under the mixture (with its wide component's
    # Gauss-Newton prior); the refinement under the component more probable at the match
    matcher = _Matcher(reference, current, cfg, x0, prior.info_search, prior.cost)
    k = math.floor(cfg.rotation_window_rad / cfg.rotation_step_rad + 1e-9)
    offsets = [0.0] + [sg * i * cfg.rotation_step_rad for i in range(1, k + 1) for sg in (1, -1)]
    # a few iterations from every start (the prior keeps each near the odometry except in
    # rotation, which the start sets); the odometry's own start and the two others of most
    # overlap are refined; the refined one of least negative log-posterior is the match
    coarse = _coarse_starts(matcher, x0, offsets, cfg)
    candidates = [coarse[0]] + sorted(coarse[1:], key=lambda c: -c[0])[:2]
    refined = [(off, _refine(matcher, x, cfg)) for _, off, x in candidates]
    # the points' evidence as a log-likelihood ratio: their summed cost over-counts it by κ
    # (measured at the odometry's own start)
    kappa = matcher.overconfidence(refined[0][1])
    best: tuple[float, float, FloatArray] | None = None
    for off, x in refined:
        obj = matcher.objective(x, kappa)
        if best is None or obj < best[0]:
            best = (obj, off, x)
    assert best is not None
    _, offset, x = best
    slip = prior.is_slip(x)
    used_cov, info_prior = (prior.cov_slip, prior.info_slip) if slip else (prior.cov, prior.info)
    if not slip and prior.slip_probability > 0.0:
        matcher.info_prior = info_prior
        x = matcher.solve(x, cfg.max_iterations, cfg.inlier_m)
    x[2] = math.remainder(float(x[2]), 2.0 * math.pi)
    cov, overlap, inl, accepted = _posterior(matcher, reference, current, x, used_cov, info_prior)
    contradicted = slip and not accepted
    return ScanMatch(
        x, cov, float(overlap), inl, float(offset), accepted, slip and accepted, contradicted
    )


def match_any_heading(
    reference: ScanPoints,
    current: ScanPoints,
    delta0: FloatArray,
    sigma_xy_m: float,
    config: ScanMatchConfig,
    refine: int = 6,
) -> tuple[ScanMatch, float]:
    """Register ``current`` against ``reference`` with no prior on the rotation between them.

    For a scan that :func:`match_scans` could not register against its prediction (a gap in
    the log, a turn faster than the prediction allows).  The search starts from every
    rotation of the circle (steps of ``rotation_step_rad``) with the translation of
    ``delta0`` under an isotropic Gaussian of ``sigma_xy_m``; the ``refine`` starts of most
    overlap after a few iterations are refined, and the distinct solutions (apart by more
    than half a rotation step or ``inlier_m``) are weighed by their posterior: the points'
    log-likelihood scaled by ``κ`` (module docstring) plus the translation prior, the
    rotation's prior being flat.  A corridor seen both ways gives two solutions of nearly
    equal weight.

    Returns
    -------
    ScanMatch
        The solution of greatest posterior (``cov`` its points' and the translation prior's
        posterior; ``accepted`` as in :func:`match_scans`; ``start_offset_rad`` the start's
        rotation from ``delta0``).
    float
        Its posterior probability among the distinct solutions found (1 when it is the only
        one).
    """
    cfg = config
    x0 = np.asarray(delta0, dtype=float)
    # the rotation's prior: flat (a standard deviation far beyond the circle)
    Q = np.diag([sigma_xy_m**2, sigma_xy_m**2, 1e6])
    prior = _OdometryPrior(x0, Q, replace(cfg, slip_probability=0.0))
    matcher = _Matcher(reference, current, cfg, x0, prior.info, prior.cost)
    n_starts = max(math.ceil(2.0 * math.pi / cfg.rotation_step_rad), 1)
    offsets = [-math.pi + i * 2.0 * math.pi / n_starts for i in range(n_starts)]
    coarse = _coarse_starts(matcher, x0, offsets, cfg)
    refined: list[tuple[float, FloatArray]] = []
    for _, off, x in sorted(coarse, key=lambda c: -c[0])[: max(refine, 1)]:
        x = _refine(matcher, x, cfg)
        x[2] = math.remainder(float(x[2]), 2.0 * math.pi)
        refined.append((off, x))
    objectives = [matcher.objective(x) for _, x in refined]
    kappa = matcher.overconfidence(refined[int(np.argmin(objectives))][1])
    # one entry per distinct solution: its least objective
    modes: list[tuple[float, float, FloatArray]] = []
    for obj, (off, x) in sorted(
        zip((matcher.objective(x, kappa) for _, x in refined), refined, strict=True),
        key=lambda t: t[0],
    ):
        if any(
            abs(math.remainder(float(x[2] - y[2]), 2.0 * math.pi)) < 0.5 * cfg.rotation_step_rad
            and math.hypot(float(x[0] - y[0]), float(x[1] - y[1])) < cfg.inlier_m
            for _, _, y in modes
        ):
            continue
        modes.append((obj, off, x))
    best_obj, offset, x = modes[0]
    probability = 1.0 / sum(math.exp(best_obj - obj) for obj, _, _ in modes)
    cov, overlap, inl, accepted = _posterior(matcher, reference, current, x, Q, prior.info)
    return ScanMatch(x, cov, float(overlap), inl, float(offset), accepted), probability


def _posterior(
    matcher: _Matcher,
    reference: ScanPoints,
    current: ScanPoints,
    x: FloatArray,
    prior_cov: FloatArray,
    info_prior: FloatArray,
) -> tuple[FloatArray, float, int, bool]:
    """``(cov, overlap, inliers, accepted)`` of the match at ``x`` under the prior.

    ``cov`` is the posterior (the points' sandwich covariance and the prior's information
    together), or ``prior_cov`` where the points' covariance is not finite or the posterior not
    positive definite (then not accepted); accepted also needs ``overlap >= min_overlap``.
    """
    cov_points, inl = matcher.covariance(x)
    overlap = inl / max(visible_points(reference, current, x), inl, 1)
    ok = bool(np.all(np.isfinite(cov_points)))
    cov: FloatArray = np.asarray(prior_cov, dtype=np.float64).copy()
    if ok:
        try:
            info = np.linalg.inv(cov_points) + info_prior
            post = np.linalg.inv(0.5 * (info + info.T))
            post = 0.5 * (post + post.T)
            ok = bool(np.all(np.linalg.eigvalsh(post) > 0.0))
            if ok:
                cov = post
        except np.linalg.LinAlgError:
            ok = False
    return cov, float(overlap), inl, ok and overlap >= matcher.cfg.min_overlap


def overlap_at(
    reference: ScanPoints, current: ScanPoints, delta: FloatArray, config: ScanMatchConfig
) -> float:
    """The overlap of ``current`` with ``reference`` at ``delta``, without matching.

    The fraction of ``current``'s points that ``reference`` could see at ``delta``
    (:func:`visible_points`) lying within ``inlier_m`` of a reference line: the measure
    :func:`match_scans` accepts a match by (``min_overlap``), at a given pose.
    """
    x = np.asarray(delta, dtype=float)
    matcher = _Matcher(reference, current, config, x, np.zeros((3, 3)), lambda x: 0.0)
    inliers = matcher.inliers(x) if matcher.p.shape[0] >= 3 else 0
    return inliers / max(visible_points(reference, current, x), inliers, 1)


def refine_scan(
    reference: ScanPoints,
    current: ScanPoints,
    delta0: FloatArray,
    prior_cov: FloatArray,
    config: ScanMatchConfig,
) -> ScanMatch:
    """Register ``current`` against ``reference`` from the odometry alone (no search).

    For a scan between two keyframes, matched against the last keyframe: its odometry since
    the keyframe covers a short stretch, so the mode of the posterior (the points' robust
    likelihood times the odometry's Gaussian ``N(delta0, prior_cov)``) is refined from the
    odometry itself, as :func:`match_scans` refines its best start (first with pairs within
    ``max_correspondence_m``, then within ``inlier_m``), without its search over rotations
    and without the slip component.

    Returns
    -------
    ScanMatch
        ``start_offset_rad`` 0, ``slip`` and ``contradicted`` False.
    """
    cfg = config
    x0 = np.asarray(delta0, dtype=float)
    Q = np.asarray(prior_cov, dtype=float)
    info = _symmetric_inverse(Q)
    matcher = _Matcher(reference, current, cfg, x0, info, lambda x: 0.0)
    x = matcher.solve(x0, cfg.max_iterations, cfg.max_correspondence_m)
    x = matcher.solve(x, cfg.max_iterations, cfg.inlier_m)
    x[2] = math.remainder(float(x[2]), 2.0 * math.pi)
    cov, overlap, inl, accepted = _posterior(matcher, reference, current, x, Q, info)
    return ScanMatch(x, cov, overlap, inl, 0.0, accepted)
