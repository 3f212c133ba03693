"""MapBuilder on synthetic line observations with known covariances (no fitter needed).

Each wall seen from a pose gives a line whose covariance is the inverse Fisher information of the
points a 0.5° scanner with the paper's noise would put on it (reading note 8); the estimate is
drawn from that covariance, so the statistics of the merge can be checked exactly.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from linefit.line import Line
from slam.errors import InputError
from slam.geometry import pose_compose, pose_exp, pose_inverse, wrap_angle
from slam.lines import align_representative
from slam.lines.config import MapConfig
from slam.lines.mapbuilder import MapBuilder

SIGMA_D, SIGMA_PHI, STEP = 0.005, 1e-4, np.deg2rad(0.5)

# A corridor 2 m wide, 20 m long: the lower wall broken by two doors, the upper wall with a
# recessed doorway 0.15 m deep (two collinear pieces and a parallel piece 0.15 m behind).
WALLS = {
    "lower": [
        ((0.0, -1.0), (5.0, -1.0)),
        ((6.0, -1.0), (12.0, -1.0)),
        ((13.0, -1.0), (20.0, -1.0)),
    ],
    "upper": [((0.0, 1.0), (8.0, 1.0)), ((9.0, 1.0), (20.0, 1.0))],
    "recess": [((8.0, 1.15), (9.0, 1.15))],
    "west": [((0.0, -1.0), (0.0, 1.0))],
    "east": [((20.0, -1.0), (20.0, 1.0))],
}


def wall_line(a, b) -> np.ndarray:
    """World line (r, α) of the segment a-b in normal form."""
    a, b = np.asarray(a), np.asarray(b)
    t = (b - a) / np.linalg.norm(b - a)
    n = np.array([t[1], -t[0]])
    r = float(n @ a)
    if r < 0:
        n, r = -n, -r
    return np.array([r, np.arctan2(n[1], n[0])])


def observe(a, b, pose, rng, max_range=8.0):
    """A Line (sensor frame) of the visible part of wall a-b seen from the true ``pose``."""
    inv = pose_inverse(pose)
    c, s = np.cos(inv[2]), np.sin(inv[2])
    R = np.array([[c, -s], [s, c]])
    pa, pb = R @ np.asarray(a) + inv[:2], R @ np.asarray(b) + inv[:2]
    d = pb - pa
    tt = d / np.linalg.norm(d)
    n = np.array([tt[1], -tt[0]])
    r = n @ pa
    if r < 0:
        n, r = -n, -r
    alpha = np.arctan2(n[1], n[0])
    t = np.array([-np.sin(alpha), np.cos(alpha)])
    sa, sb = sorted([pa @ t, pb @ t])
    lim = np.sqrt(max(max_range**2 - r**2, 0.0))
    sa, sb = max(sa, -lim), min(sb, lim)
    if r < 0.3 or sb - sa < 0.3:
        return None
    phi0, phi1 = alpha + np.arctan(sa / r), alpha + np.arctan(sb / r)
    phi = np.arange(np.ceil(phi0 / STEP), np.floor(phi1 / STEP) + 1) * STEP
    if phi.size < 5:
        return None
    u_s = r * np.tan(phi - alpha)
    dist = np.hypot(r, u_s)
    # Eq. 8 projected on n and t
    cn = np.cos(phi - alpha)
    sn = np.sin(phi - alpha)
    P_R = SIGMA_D**2 * cn**2 + dist**2 * SIGMA_PHI**2 * sn**2
    P_S = SIGMA_D**2 * sn**2 + dist**2 * SIGMA_PHI**2 * cn**2
    J = np.stack([-np.ones_like(u_s), u_s], 1)
    info = (J / P_R[:, None]).T @ J
    s_true = np.sum(u_s / P_S) / np.sum(1 / P_S)
    cov = np.zeros((3, 3))
    cov[:2, :2] = np.linalg.inv(info)
    cov[2, 2] = 1 / np.sum(1 / P_S)
    x = np.array([r, alpha, s_true]) + rng.multivariate_normal(np.zeros(3), cov)
    ends = np.array([u_s[0], u_s[-1]]) + rng.normal(0, np.sqrt([P_S[0], P_S[-1]]))
    return Line(
        r=x[0],
        alpha=float(wrap_angle(x[1])),
        s=x[2],
        cov=cov,
        segments_s=np.sort(ends)[None],
        segments_var=np.array([[P_S[0], P_S[-1]]]),
        n_points=phi.size,
    )


def poses_along(n: int) -> np.ndarray:
    x = np.linspace(1.5, 18.5, n)
    return np.column_stack([x, 0.1 * np.sin(x), 0.05 * np.cos(3 * x)])


def make_scans(rng, n_poses, pose_cov):
    """Per pose: (lines, estimated pose, labels) with the estimate drawn around the truth."""
    scans = []
    L = np.linalg.cholesky(pose_cov + 1e-300 * np.eye(3)) if pose_cov.any() else np.zeros((3, 3))
    for pose in poses_along(n_poses):
        lines, labels = [], []
        for name, pieces in WALLS.items():
            for a, b in pieces:
                ln = observe(a, b, pose, rng)
                if ln is not None:
                    lines.append(ln)
                    labels.append(name)
        est = pose_compose(pose, pose_exp(L @ rng.normal(size=3)))
        scans.append((lines, est, labels))
    return scans


def build(scans, pose_cov, config=None):
    b = MapBuilder(config or MapConfig())
    for lines, pose, _ in scans:
        b.add_scan(lines, pose, pose_cov)
    return b


def match(line_map, truth_r_alpha):
    """Index of the map line closest to a true line (in normal-form (r, α))."""
    ra = line_map.r_alpha()
    al, _, _ = align_representative(ra, np.zeros((len(ra), 2, 2)), truth_r_alpha[1])
    d = np.abs(al[:, 0] - truth_r_alpha[0]) + np.abs(wrap_angle(al[:, 1] - truth_r_alpha[1]))
    return int(np.argmin(d)), float(np.min(d))


POSE_COV = np.diag([0.02**2, 0.02**2, 0.003**2])


def test_corridor_structure_doors_and_recess(rng):
    scans = make_scans(rng, 8, POSE_COV)
    b = build(scans, POSE_COV)
    m = b.line_map()
    # five true lines: lower (3 pieces), upper (2 pieces), recess, west, east
    assert len(m) == 5, [(ln.r, ln.alpha, ln.n_observations) for ln in m.lines]
    lower = m.lines[match(m, wall_line(*WALLS["lower"][0]))[0]]
    upper = m.lines[match(m, wall_line(*WALLS["upper"][0]))[0]]
    recess = m.lines[match(m, wall_line(*WALLS["recess"][0]))[0]]
    assert lower.segments.shape[0] == 3
    assert upper.segments.shape[0] == 2
    assert recess.id not in (upper.id, lower.id)
    # segment ends near the true door edges (x = 5, 6, 12, 13)
    xs = np.sort(lower.segments[:, :, 0].ravel())
    np.testing.assert_allclose(xs[1:5], [5, 6, 12, 13], atol=0.1)
    assert sum(ln.n_observations for ln in m.lines) == sum(len(s[0]) for s in scans)
    # the candidate pairs are a small part of all new × map pairs
    assert b.stats.candidate_pairs_tested > 0


def test_merged_lines_are_consistent_nees(rng):
    nees = []
    for _ in range(25):
        scans = make_scans(rng, 8, POSE_COV)
        m = build(scans, POSE_COV).line_map()
        for name in ("lower", "upper", "west", "east"):
            truth = wall_line(*WALLS[name][0])
            k, _ = match(m, truth)
            ln = m.lines[k]
            al, P, _ = align_representative(np.array([ln.r, ln.alpha]), ln.cov_r_alpha, truth[1])
            e = al - truth
            e[1] = wrap_angle(e[1])
            nees.append(e @ np.linalg.solve(P, e))
    nees = np.array(nees)
    n = nees.size
    lo, hi = chi2.ppf([0.001, 0.999], 2 * n)
    assert lo <= nees.sum() <= hi, nees.mean()


def test_result_depends_little_on_scan_order(rng):
    scans = make_scans(rng, 10, POSE_COV)
    fwd = build(scans, POSE_COV).line_map()
    bwd = build(scans[::-1], POSE_COV).line_map()
    assert len(fwd) == len(bwd)
    assert fwd.n_segments == bwd.n_segments
    for ln in fwd.lines:
        k, d = match(bwd, np.array([ln.r, ln.alpha]))
        assert d < 1e-6 + 3 * np.sqrt(ln.cov[0, 0] + ln.cov[1, 1])
        assert bwd.lines[k].n_observations == ln.n_observations


def test_far_collinear_walls_follow_max_gap(rng):
    walls = [((0.0, 2.0), (3.0, 2.0)), ((8.0, 2.0), (11.0, 2.0))]
    lines = [observe(a, b, np.array([5.5, 0.0, 0.0]), rng, max_range=20) for a, b in walls]
    b = MapBuilder(MapConfig(max_gap_m=1.5))
    b.add_scan(lines, np.array([5.5, 0.0, 0.0]), np.zeros((3, 3)))
    assert len(b) == 2
    b = MapBuilder(MapConfig(max_gap_m=float("inf")))  # the paper: no spatial condition
    b.add_scan(lines, np.array([5.5, 0.0, 0.0]), np.zeros((3, 3)))
    m = b.line_map()
    assert len(m) == 1 and m.lines[0].segments.shape[0] == 2


def test_two_faces_of_a_thin_wall_stay_apart(rng):
    # wall 0.1 m thick at y ∈ [1.95, 2.05], seen from below and from above with a loose pose
    below = observe((0, 1.95), (6, 1.95), np.array([3.0, 0.0, 0.3]), rng)
    above = observe((0, 2.05), (6, 2.05), np.array([3.0, 4.0, -2.0]), rng)
    loose = np.diag([0.1, 0.1, 0.01])
    b = MapBuilder()
    b.add_scan([below], np.array([3.0, 0.0, 0.3]), loose)
    b.add_scan([above], np.array([3.0, 4.0, -2.0]), loose)
    assert len(b) == 2
    b = MapBuilder(MapConfig(same_side=False))
    b.add_scan([below], np.array([3.0, 0.0, 0.3]), loose)
    b.add_scan([above], np.array([3.0, 4.0, -2.0]), loose)
    assert len(b) == 1


def test_within_scan_pieces_merge_and_bad_input(rng):
    pose = np.array([10.0, 0.0, 0.0])
    lines = [observe(a, b, pose, rng) for a, b in WALLS["lower"]]
    b = MapBuilder()
    assert b.add_scan([ln for ln in lines if ln is not None], pose, np.zeros((3, 3))) == 1
    assert b.line_map().lines[0].segments.shape[0] == 3
    with pytest.raises(InputError, match="pose_world_laser"):
        b.add_scan(lines[:1], np.array([np.nan, 0, 0]))
    assert b.add_scan([], pose) == 1


def test_spatial_prefilter_changes_cost_not_result(rng):
    scans = make_scans(rng, 8, POSE_COV)
    fast = build(scans, POSE_COV)
    slow = MapBuilder(MapConfig(), spatial_prefilter=False)
    for lines, pose, _ in scans:
        slow.add_scan(lines, pose, POSE_COV)
    a, b = fast.line_map(), slow.line_map()
    assert len(a) == len(b) and a.n_segments == b.n_segments
    np.testing.assert_allclose(a.r_alpha(), b.r_alpha(), atol=1e-12)
    assert fast.stats.candidate_pairs_tested < slow.stats.candidate_pairs_tested
