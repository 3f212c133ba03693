"""Where a run's error entered (slam.evaluation.onsets): known answers on constructed runs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from slam.errors import EvaluationError
from slam.evaluation.onsets import error_onsets
from slam.evaluation.relations_metric import relation_errors
from slam.evaluation.timestamps import match_timestamps
from slam.geometry import pose_between
from slam.io.relations import read_relations
from slam.io.tum import read_tum

DEMO = Path(__file__).resolve().parents[1] / "datasets" / "sim" / "demo"


def _run_with_steps(steps: list[tuple[float, float, float]], seed: int = 1):
    """A robot driving a circle for 200 s (a scan every 0.5 s) and 800 relations 0.5-60 s long;
    the estimate is the truth with each step ``(time, dx, dy)`` added to every pose after its
    time (in the world frame).  Returns ``(t1, t2, translation errors)``."""
    t = np.arange(0.0, 200.0, 0.5)
    truth = np.column_stack([10 * np.cos(t / 40), 10 * np.sin(t / 40), t / 40 + np.pi / 2])
    est = truth.copy()
    for when, dx, dy in steps:
        est[t > when, :2] += (dx, dy)
    rng = np.random.default_rng(seed)
    i1 = rng.integers(0, t.size - 2, 800)
    i2 = np.minimum(i1 + rng.integers(1, 121, 800), t.size - 1)
    d_est = pose_between(est[i1], est[i2])[:, :2]
    d_true = pose_between(truth[i1], truth[i2])[:, :2]
    err = np.hypot(*(d_est - d_true).T) + rng.uniform(0.0, 0.01, 800)  # 1 cm of scatter
    return t[i1], t[i2], err


def test_one_wrong_step_is_found_where_it_happened():
    t1, t2, err = _run_with_steps([(80.25, 0.6, 0.8)])
    onsets = error_onsets(t1, t2, err, threshold_m=0.2)
    assert len(onsets) == 1
    (o,) = onsets
    assert o.from_s <= 80.25 < o.until_s
    assert o.until_s - o.from_s <= 2.0  # located to a few scans
    spanning = (np.minimum(t1, t2) <= 80.25) & (np.maximum(t1, t2) > 80.25)
    assert o.bad == int(spanning.sum()) and o.good == 0
    assert o.mean_error_m == pytest.approx(1.0, abs=0.01)
    # either order of a relation's stamps
    swapped = error_onsets(t2, t1, err, threshold_m=0.2)
    assert swapped == onsets


def test_a_step_taken_back_later_gives_two_onsets():
    """A wrong step at 50 s that a closure takes back at 90 s: the relations spanning both are
    right, those spanning one err by the step."""
    t1, t2, err = _run_with_steps([(50.25, 1.0, 0.0), (90.25, -1.0, 0.0)])
    onsets = error_onsets(t1, t2, err, threshold_m=0.2)
    assert len(onsets) == 2
    found = sorted(onsets, key=lambda o: o.from_s)
    assert found[0].from_s <= 50.25 < found[0].until_s
    assert found[1].from_s <= 90.25 < found[1].until_s
    lo, hi = np.minimum(t1, t2), np.maximum(t1, t2)
    both = (lo <= 50.25) & (hi > 90.25)
    assert both.sum() > 0 and found[0].good == int(both.sum())
    assert sum(o.bad for o in onsets) == int(np.count_nonzero(err > 0.2))


def test_no_onset_without_bad_relations():
    t1, t2, err = _run_with_steps([(80.25, 0.6, 0.8)])
    assert error_onsets(t1, t2, err, threshold_m=2.0) == []
    t1, t2, err = _run_with_steps([])
    assert error_onsets(t1, t2, err, threshold_m=0.2) == []
    # a few bad relations are not an onset
    assert error_onsets(t1, t2, err, threshold_m=0.2, min_relations=1) == []


def test_bad_input_is_refused():
    with pytest.raises(EvaluationError, match="one length"):
        error_onsets([0.0, 1.0], [1.0], [0.1, 0.2], 0.2)
    with pytest.raises(EvaluationError, match="finite"):
        error_onsets([0.0, np.nan], [1.0, 2.0], [0.1, 0.2], 0.2)
    with pytest.raises(EvaluationError, match="threshold_m"):
        error_onsets([0.0], [1.0], [0.1], -1.0)


def test_a_wrong_step_in_the_demo_trajectory_is_found_by_its_relations():
    """The demo's ground truth with a 0.5 m, 0.05 rad step at its 200th pose, scored on the
    demo's own relations by the relations metric's error: the onset holds the step."""
    truth = read_tum(DEMO / "ground_truth.tum")
    rel = read_relations(DEMO / "relations.txt")
    est = truth.poses.copy()
    k = 200
    when = 0.5 * (truth.timestamps[k - 1] + truth.timestamps[k])
    # every pose from k on moved as the robot would be by a wrong step between k - 1 and k
    c, s = np.cos(0.05), np.sin(0.05)
    pivot = est[k - 1, :2]
    d = est[k:, :2] - pivot
    est[k:, :2] = pivot + np.column_stack([c * d[:, 0] - s * d[:, 1], s * d[:, 0] + c * d[:, 1]])
    est[k:, :2] += 0.5 * np.array([np.cos(est[k - 1, 2]), np.sin(est[k - 1, 2])])
    est[k:, 2] += 0.05
    i1, ok1 = match_timestamps(rel.t1, truth.timestamps, 1e-5)
    i2, ok2 = match_timestamps(rel.t2, truth.timestamps, 1e-5)
    assert np.all(ok1 & ok2)
    err, _ = relation_errors(est[i1], est[i2], rel)
    exact, _ = relation_errors(truth.poses[i1], truth.poses[i2], rel)
    assert exact.max() < 0.01  # the demo's relations are its ground truth's
    onsets = error_onsets(rel.t1, rel.t2, err, threshold_m=0.1)
    assert len(onsets) >= 1
    assert onsets[0].from_s <= when < onsets[0].until_s
    spanning = (np.minimum(rel.t1, rel.t2) < when) & (np.maximum(rel.t1, rel.t2) > when)
    assert onsets[0].bad == int(np.count_nonzero(spanning & (err > 0.1)))


def test_a_turn_made_standing_still_is_placed_by_the_rotation_error():
    """A robot drives, stands still from 50 to 70 s and drives on; at 55 s, standing, the
    estimate turns 0.5 rad too far (every later pose rotated about where it stands).  The
    relations spanning 55 s but ending before 70 s err in rotation only, so by translation
    the good relations outnumber the bad ones everywhere and no onset holds 55 s; by
    rotation the onset holds it (``scripts/error_onsets.py --threshold-deg``)."""
    t = np.arange(0.0, 120.0, 0.5)
    speed = np.where((t >= 50.0) & (t < 70.0), 0.0, 0.5)
    x = np.concatenate([[0.0], np.cumsum(speed[1:] * 0.5)])
    truth = np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])
    est = truth.copy()
    after = t > 55.0
    pivot = truth[np.searchsorted(t, 55.0), :2]
    c, s = np.cos(0.5), np.sin(0.5)
    d = est[after, :2] - pivot
    est[after, :2] = pivot + np.column_stack([c * d[:, 0] - s * d[:, 1], s * d[:, 0] + c * d[:, 1]])
    est[after, 2] += 0.5
    rng = np.random.default_rng(3)
    i1 = rng.integers(0, t.size - 2, 1500)
    i2 = np.minimum(i1 + rng.integers(1, 61, 1500), t.size - 1)
    d_est, d_true = pose_between(est[i1], est[i2]), pose_between(truth[i1], truth[i2])
    trans = np.hypot(*(d_est[:, :2] - d_true[:, :2]).T)
    rot_deg = np.rad2deg(np.abs(np.angle(np.exp(1j * (d_est[:, 2] - d_true[:, 2])))))
    by_rotation = error_onsets(t[i1], t[i2], rot_deg, threshold_m=10.0)
    by_translation = error_onsets(t[i1], t[i2], trans, threshold_m=0.2)
    assert by_rotation[0].from_s <= 55.0 < by_rotation[0].until_s
    assert by_rotation[0].good == 0
    assert np.count_nonzero(trans > 0.2) > 30  # the step does show in translation
    assert not any(o.from_s <= 55.0 < o.until_s for o in by_translation)
