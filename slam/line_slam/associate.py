"""Association of a keyframe's lines: where each line goes after the registration.

Lines paired with a graph landmark become line factors (:meth:`LandmarkBook.observe`).  Lines
paired with a tentative landmark are buffered there (:mod:`slam.frontend.tentative`); a
tentative landmark seen in ``tentative.min_observations`` keyframes is promoted to a graph
landmark with all its observations, and one not seen for ``tentative.max_age_keyframes``
keyframes expires.  Lines compatible with nothing start tentative landmarks; lines compatible
with some landmark but not paired are dropped as ambiguous.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from slam.frontend.config import TentativeConfig
from slam.line_slam.front_end import Registration
from slam.line_slam.landmarks import LandmarkBook
from slam.line_slam.local_map import GRAPH, TENTATIVE, LocalMap
from slam.line_slam.observations import ScanLines

__all__ = ["Association", "associate_lines"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


@dataclass(frozen=True, eq=False)
class Association:
    """Outcome of :func:`associate_lines`.

    Attributes
    ----------
    factors : ndarray of int
        Line factors added (to graph landmarks, and those of promoted tentative ones).
    matched : ndarray of bool, shape (K,)
        Lines paired with a landmark (graph or tentative).
    new : ndarray of int
        Lines that started a tentative landmark.
    ambiguous : int
        Lines dropped as ambiguous.
    """

    factors: IntArray
    matched: NDArray[np.bool_]
    new: IntArray
    ambiguous: int


def associate_lines(
    book: LandmarkBook,
    pose: int,
    lines: ScanLines,
    reg: Registration,
    local: LocalMap,
    config: TentativeConfig,
    counters: dict[str, int],
) -> Association:
    """Route the lines of keyframe ``pose`` (module docstring); counts in ``counters``."""
    K = len(lines)
    x0 = reg.pose_world_laser
    matches, n_compat = reg.matches, reg.n_compatible
    matched = matches >= 0
    kind = np.full(K, -1, dtype=np.intp)
    target = np.full(K, -1, dtype=np.intp)
    kind[matched] = local.kind[matches[matched]]
    target[matched] = local.index[matches[matched]]
    to_graph = np.flatnonzero(matched & (kind == GRAPH))
    to_tent = np.flatnonzero(matched & (kind == TENTATIVE))
    new = np.flatnonzero(~matched & (n_compat == 0))
    ambiguous = int(np.count_nonzero(~matched & (n_compat > 0)))
    factors = book.observe(pose, target[to_graph], lines, to_graph, x0)
    # tentative landmarks: observe, start, promote, expire
    tp = book.tentative
    if to_tent.size:
        tp.observe(target[to_tent], pose, x0, [lines.observation(pose, int(k)) for k in to_tent])
    if new.size:
        tp.add(pose, x0, [lines.observation(pose, int(k)) for k in new])
        counters["tentative_started"] += int(new.size)
    ready = tp.ready(config.min_observations)
    promoted = book.promote(ready)
    counters["tentative_promoted"] += int(ready.size)
    factors = np.concatenate([factors, promoted])
    expired = tp.expired(pose, config.max_age_keyframes)
    tp.remove(expired)
    counters["tentative_expired"] += int(expired.size)
    counters["lines_matched"] += int(matched.sum())
    counters["lines_new"] += int(new.size)
    counters["lines_ambiguous"] += ambiguous
    return Association(factors, matched, new, ambiguous)
