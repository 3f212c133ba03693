"""The public logs: counts, beams, time spans (datasets README) and the odometry baseline."""

from __future__ import annotations

import numpy as np
import pytest

from slam.evaluation import relations_metric
from slam.io import CarmenStats, iter_scans, read_relations, resolve_log, verify_dataset
from slam.io.trajectory import Trajectory

pytestmark = pytest.mark.realdata

# From ../shared/datasets/README.md ("Datasets" and "Odometry-only baseline").
FACTS = {
    "intel": dict(
        scans=13631,
        odom=26915,
        beams=180,
        first=976052857.337530,
        last=976055548.633890,
        backward=631,
        largest_back=0.897,
        relations=2984,
    ),
    "aces": dict(
        scans=7374,
        odom=7375,
        beams=180,
        first=70.289900,
        last=1435.809999,
        backward=0,
        largest_back=0.0,
        relations=1279,
    ),
    "fr079": dict(
        scans=4934,
        odom=8951,
        beams=360,
        first=1211.520329,
        last=2272.970282,
        backward=0,
        largest_back=0.0,
        relations=1685,
    ),
}
# abs trans, sqr trans, abs rot, sqr rot: (mean, std) printed with 4 decimals
BASELINE = {
    "intel": [(7.3730, 14.4587), (263.3453, 796.3836), (39.1663, 53.7996), (4427.4227, 7490.0973)],
    "aces": [(0.5636, 2.7247), (7.7359, 47.1602), (2.3275, 6.5060), (47.7121, 240.1551)],
    "fr079": [(6.5425, 13.6576), (229.2232, 646.5105), (30.2922, 45.5340), (2989.7293, 6142.9528)],
}


@pytest.fixture(scope="module", params=sorted(FACTS))
def log_pass(request, shared_data):
    log = resolve_log(request.param, root=shared_data)
    stats = CarmenStats()
    stamps, poses, beams, max_ranges = [], [], set(), set()
    for scan in iter_scans(log.log, stats=stats):
        stamps.append(scan.timestamp)
        poses.append(scan.pose_odom_base)
        beams.add(scan.n_beams)
        max_ranges.add(scan.max_range_m)
    return request.param, log, stats, np.array(stamps), np.array(poses), beams, max_ranges


def test_counts_beams_and_time_spans(log_pass):
    name, log, stats, stamps, _, beams, max_ranges = log_pass
    facts = FACTS[name]
    assert stats.scans == facts["scans"] and stats.odometry == facts["odom"]
    assert stats.malformed == 0 and stats.unknown == 0 and stats.comments == 4
    assert beams == {facts["beams"]}
    assert max_ranges == {log.manifest.laser.max_range_m}
    assert stamps.min() == pytest.approx(facts["first"], abs=1e-6)
    assert stamps.max() == pytest.approx(facts["last"], abs=1e-6)
    steps = np.diff(stamps)
    assert int((steps < 0).sum()) == facts["backward"]
    assert -steps.min(initial=0.0) == pytest.approx(facts["largest_back"], abs=5e-4)
    assert np.unique(stamps).size == stamps.size
    assert stats.scans == log.manifest.scans


def test_odometry_only_relations_metric_matches_readme(log_pass):
    name, log, _, stamps, poses, _, _ = log_pass
    metric = relations_metric(Trajectory(stamps, poses), read_relations(log.relations))
    assert metric.n_used == FACTS[name]["relations"] and metric.n_unmatched == 0
    got = [metric.abs_trans_m, metric.sqr_trans_m2, metric.abs_rot_deg, metric.sqr_rot_deg2]
    for value, (mean, std) in zip(got, BASELINE[name], strict=True):
        assert round(value.mean, 4) == pytest.approx(mean, abs=1e-9)
        assert round(value.std, 4) == pytest.approx(std, abs=1e-9)


def test_timestamp_mistake_fails_loudly(log_pass):
    """Stamps off by 1 ms (e.g. rounded, or another field) match no relation: an error."""
    _, log, _, stamps, poses, _, _ = log_pass
    from slam.errors import EvaluationError

    with pytest.raises(EvaluationError, match="time stamp"):
        relations_metric(Trajectory(stamps + 1e-3, poses), read_relations(log.relations))


def test_catalogue_checksums_match_the_files(shared_data):
    from slam.io import load_catalog

    for manifest in load_catalog().values():
        status = verify_dataset(manifest, shared_data)
        assert status.present and status.intact, status.problems
