"""Joining collinear lines of one scan into one line with several segments (step 6)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from linefit.config import LineFitConfig
from linefit.fit import PointSet
from linefit.fitted import Fitted, Groups
from linefit.line import wrap_angle
from linefit.refine import refine

__all__ = ["merge_collinear"]

FloatArray = NDArray[np.float64]


def merge_collinear(
    pts: PointSet, sigma_range: FloatArray, fitted: Fitted, cfg: LineFitConfig
) -> Fitted:
    """Join lines of one scan whose (r, α) pass the χ² test into multi-segment lines."""
    G = fitted.n_groups
    if G < 2:
        return fitted
    perm = np.argsort(fitted.gscan, kind="stable")  # lines by scan
    gscan = fitted.gscan[perm]
    first_g = np.searchsorted(gscan, gscan, side="left")
    per_scan = np.searchsorted(gscan, gscan, side="right") - first_g
    k_max = int(per_scan.max())
    if k_max < 2:
        return fitted
    # all pairs (i < j) of lines within each scan
    ti, tj = np.triu_indices(k_max, 1)
    starts = np.unique(first_g)
    sizes = np.searchsorted(gscan, gscan[starts], side="right") - starts
    ok = tj[None, :] < sizes[:, None]
    i = perm[(starts[:, None] + ti[None, :])[ok]]
    j = perm[(starts[:, None] + tj[None, :])[ok]]
    r, alpha = fitted.fit.r, fitted.fit.alpha
    flip = r < 0.0
    rn = np.abs(r)
    an = np.asarray(wrap_angle(np.where(flip, alpha + np.pi, alpha)))
    P = fitted.cov.cov[:, :2, :2]
    p_ra = np.where(flip, -P[:, 0, 1], P[:, 0, 1])
    dr = rn[i] - rn[j]
    da = np.asarray(wrap_angle(an[i] - an[j]))
    s00 = P[i, 0, 0] + P[j, 0, 0]
    s11 = P[i, 1, 1] + P[j, 1, 1]
    s01 = p_ra[i] + p_ra[j]
    det = s00 * s11 - s01 * s01
    with np.errstate(divide="ignore", invalid="ignore"):
        d2 = (s11 * dr * dr - 2.0 * s01 * dr * da + s00 * da * da) / det
    cand = np.flatnonzero(d2 <= cfg.merge_chi2)
    if cand.shape[0] == 0:
        return fitted
    parent = list(range(G))

    def find(a: int) -> int:
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for k in cand[np.argsort(d2[cand], kind="stable")].tolist():
        a, b = find(int(i[k])), find(int(j[k]))
        if a != b:
            parent[max(a, b)] = min(a, b)
    roots = np.array([find(a) for a in range(G)])
    joined = np.bincount(roots, minlength=G)[roots] > 1
    if not joined.any():
        return fitted
    # only the joined lines are refitted (from the angle of the set's first line)
    _, new_g = np.unique(roots[joined], return_inverse=True)
    new_g = new_g.reshape(-1)
    n_new = int(new_g.max()) + 1
    g_of = np.full(G, -1, dtype=np.intp)
    g_of[joined] = new_g
    members = joined[fitted.gidx]
    gidx = g_of[fitted.gidx[members]]
    pidx = fitted.pidx[members]
    # a point shared by two joined lines counts once; memberships sorted by new line
    key = gidx.astype(np.int64) * (len(pts) + 1) + pidx
    _, first = np.unique(key, return_index=True)
    joined_ids = np.flatnonzero(joined)
    _, first_of_set = np.unique(new_g, return_index=True)
    grp = Groups(
        pidx=pidx[first],
        gidx=gidx[first],
        n=n_new,
        alpha0=alpha[joined_ids[first_of_set]],
        gscan=fitted.gscan[joined_ids[first_of_set]],
    )
    refined = refine(pts, sigma_range, grp, cfg)
    rest = fitted.select(~joined)
    return rest if refined is None else Fitted.concat(rest, refined)
