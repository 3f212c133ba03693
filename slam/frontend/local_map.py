"""A local map of recent key scans: the reference a scan is registered against.

Matching each scan against one earlier scan chains one match per reference, and a single
scan's walls can be ambiguous along their own direction (a corridor seen in ranges written
in steps gives several solutions a few centimetres apart).  :class:`LocalMap` keeps the last
key scans (each with its pose) that lie within ``path_m`` of travel and ``turn_rad`` of
turning of the newest, and merges their points into the newest key scan's frame: the walls
then hold the points of several viewpoints, and a scan is matched against all of them at once,
as kiss-icp registers against its local map rather than against the last scan.

The merged points keep each scan's own local lines (normals) and Eq. 8 covariances, rotated
into the newest key scan's frame, and each scan's pieces of wall stay separate segments (their
model error is the scan's).  What the map could see (:attr:`ScanPoints.view`, for the
overlap) is the newest key scan's view.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from slam.frontend.scan_match import ScanPoints, scan_view
from slam.geometry import pose_between
from slam.validate import nonneg

__all__ = ["LocalMap", "transform_points"]

FloatArray = NDArray[np.float64]


def transform_points(points: ScanPoints, pose: FloatArray) -> ScanPoints:
    """``points`` moved by ``pose`` ``(x, y, θ)``: their frame's pose in the new frame.

    Points and normals are rotated and translated, covariances rotated (``R Q Rᵀ``); the
    local lines and segments are kept; the view is dropped (a moved scan's beams no longer
    start at the new frame's origin).
    """
    c, s = math.cos(float(pose[2])), math.sin(float(pose[2]))
    xy = points.xy
    moved = np.empty_like(xy)
    moved[:, 0] = c * xy[:, 0] - s * xy[:, 1] + float(pose[0])
    moved[:, 1] = s * xy[:, 0] + c * xy[:, 1] + float(pose[1])
    normals = np.empty_like(points.normals)
    normals[:, 0] = c * points.normals[:, 0] - s * points.normals[:, 1]
    normals[:, 1] = s * points.normals[:, 0] + c * points.normals[:, 1]
    a, b, d = points.q11, points.q12, points.q22
    # R Q Rᵀ with R = [[c, −s], [s, c]]
    q11 = c * c * a - 2.0 * c * s * b + s * s * d
    q12 = c * s * (a - d) + (c * c - s * s) * b
    q22 = s * s * a + 2.0 * c * s * b + c * c * d
    return ScanPoints(
        moved, q11, q12, q22, normals, points.has_normal, points.segment, points.noise_ratio
    )


class LocalMap:
    """The last key scans within ``path_m`` of travel and ``turn_rad`` of turning.

    Parameters
    ----------
    path_m, turn_rad : float
        An older key scan stays while the travel (summed translations between consecutive key
        scans, m) and the turning (summed absolute rotations, rad) from it to the newest are
        both within these.  0 and 0: the newest key scan alone.
    """

    def __init__(self, path_m: float, turn_rad: float) -> None:
        nonneg("path_m", path_m)
        nonneg("turn_rad", turn_rad)
        self.path_m = path_m
        self.turn_rad = turn_rad
        # (pose in the odometry frame, points, travel and turning from the previous key scan)
        self._keys: deque[tuple[FloatArray, ScanPoints, float, float]] = deque()
        self._merged: ScanPoints | None = None

    def __len__(self) -> int:
        return len(self._keys)

    def reset(self) -> None:
        """Forget every key scan."""
        self._keys.clear()
        self._merged = None

    def add(self, pose: FloatArray, points: ScanPoints) -> None:
        """Make ``points`` (a scan at ``pose`` in the odometry frame) the newest key scan."""
        pose = np.asarray(pose, dtype=float).copy()
        step_m, step_rad = 0.0, 0.0
        if self._keys:
            step = pose_between(self._keys[-1][0], pose)
            step_m, step_rad = math.hypot(step[0], step[1]), abs(float(step[2]))
        self._keys.append((pose, points, step_m, step_rad))
        # drop the oldest while the travel or turning from it to the newest is too long
        while len(self._keys) > 1:
            travel = sum(k[2] for k in list(self._keys)[1:])
            turning = sum(k[3] for k in list(self._keys)[1:])
            if travel <= self.path_m and turning <= self.turn_rad:
                break
            self._keys.popleft()
        self._merged = None

    @property
    def pose(self) -> FloatArray:
        """The newest key scan's pose in the odometry frame ``(x, y, θ)``."""
        return self._keys[-1][0].copy()

    @property
    def points(self) -> ScanPoints:
        """The key scans' points in the newest key scan's frame, with its view."""
        if self._merged is None:
            self._merged = self._merge()
        return self._merged

    def _merge(self) -> ScanPoints:
        newest_pose, newest, _, _ = self._keys[-1]
        view = scan_view(newest)
        if len(self._keys) == 1:
            return replace(newest, view=view)
        parts = [newest]
        for pose, points, _, _ in list(self._keys)[:-1]:
            parts.append(transform_points(points, pose_between(newest_pose, pose)))
        segments = []
        offset = 0
        for part in parts:
            seg = part.segment.copy()
            seg[seg >= 0] += offset
            offset += int(part.segment.max(initial=-1)) + 1
            segments.append(seg)
        return ScanPoints(
            np.concatenate([p.xy for p in parts]),
            np.concatenate([p.q11 for p in parts]),
            np.concatenate([p.q12 for p in parts]),
            np.concatenate([p.q22 for p in parts]),
            np.concatenate([p.normals for p in parts]),
            np.concatenate([p.has_normal for p in parts]),
            np.concatenate(segments),
            newest.noise_ratio,
            view,
        )
