"""Which scan pairs of a simulated log get a ground-truth relation.

The choice (short pairs along the path, revisits, random pairs) is documented on
:class:`~slam.sim.config.RelationsConfig`.  The relation itself is ``pose(i)⁻¹ · pose(j)`` of
the true laser poses, written by :func:`slam.io.relations.write_relations`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from linefit.line import wrap_angle
from slam.errors import InputError
from slam.sim.config import RelationsConfig

__all__ = ["relation_pairs"]

IntArray = NDArray[np.int64]


def relation_pairs(
    poses_world_laser: ArrayLike, config: RelationsConfig, rng: np.random.Generator
) -> IntArray:
    """Index pairs ``(i, j)``, ``i < j``, sorted and unique, shape ``(m, 2)``.

    Parameters
    ----------
    poses_world_laser : array_like, shape (n, 3)
        True laser poses in file (time) order.
    config : RelationsConfig
        How many pairs of each kind.
    rng : numpy.random.Generator
        Draws the revisit and random pairs.
    """
    p = np.asarray(poses_world_laser, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise InputError(f"poses_world_laser must have shape (n, 3), got {p.shape}")
    n = p.shape[0]
    if n < 2:
        return np.zeros((0, 2), dtype=np.int64)
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p[:, :2], axis=0), axis=1))])
    chunks: list[IntArray] = []
    # Short pairs: scan i and the first scan at least d further along the path.
    first = np.arange(0, n, config.short_stride)
    for d in config.short_distances_m:
        j = np.searchsorted(s, s[first] + d, side="left")
        keep = j < n
        chunks.append(np.column_stack([first[keep], j[keep]]))
    # Revisits: close in space and heading, far apart along the path.
    if config.n_revisits > 0:
        tree = cKDTree(p[:, :2])
        cand = tree.query_pairs(config.revisit_max_distance_m, output_type="ndarray")
        if cand.shape[0]:
            cand = np.sort(cand, axis=1)
            dtheta = np.abs(np.asarray(wrap_angle(p[cand[:, 1], 2] - p[cand[:, 0], 2])))
            ok = (s[cand[:, 1]] - s[cand[:, 0]] >= config.revisit_min_path_m) & (
                dtheta <= np.deg2rad(config.revisit_max_angle_deg)
            )
            cand = cand[ok]
            # Sort first so that the draw does not depend on cKDTree's output order.
            cand = cand[np.lexsort((cand[:, 1], cand[:, 0]))]
            if cand.shape[0] > config.n_revisits:
                cand = cand[rng.choice(cand.shape[0], config.n_revisits, replace=False)]
            chunks.append(cand.astype(np.int64))
    # Random pairs over the whole log.
    if config.n_random > 0:
        i = rng.integers(0, n, config.n_random)
        j = rng.integers(0, n, config.n_random)
        pairs = np.sort(np.column_stack([i, j]), axis=1)
        chunks.append(pairs[pairs[:, 0] != pairs[:, 1]])
    if not chunks:
        return np.zeros((0, 2), dtype=np.int64)
    out = np.unique(np.concatenate(chunks).astype(np.int64), axis=0)
    return out.reshape(-1, 2)
