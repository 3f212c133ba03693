"""Line SLAM on excerpts of the public logs, against their Kümmerle relations (regression).

Each case runs ``lineslam slam``'s pipeline (:func:`slam.runner.run_slam`, default
configuration, the same for every log) on the first scans of a log and evaluates the relations
whose two time stamps both fall inside the excerpt.  The bounds are the errors measured when
the test was written plus a margin of about a quarter (see ``docs/real-logs.md``): a change that
makes the estimate worse on real data fails here.  The Intel excerpt contains the first loop
(scans ~300 and ~1980 see the same room), so it also guards loop closing; there the estimate
must beat odometry by far.
"""

from __future__ import annotations

import json
from dataclasses import replace
from itertools import islice
from pathlib import Path

import numpy as np
import pytest

from slam.blas import CORETYPE, kernels_in_use
from slam.config import RunConfig
from slam.evaluation import relations_metric, relations_within
from slam.io.carmen import iter_scans
from slam.io.catalog import resolve_log
from slam.io.relations import read_relations
from slam.io.trajectory import Trajectory
from slam.io.tum import read_tum
from slam.runner import run_slam

# (log, scans, bound on the mean abs translational error (m), on the rotational error (deg),
#  required ratio odometry error / our error)
CASES = [
    # measured: 0.0166 m, 0.215° (odometry 0.189 m, 3.94°), 246 relations
    pytest.param("intel", 2000, 0.021, 0.27, 5.0, id="intel-2000"),
    # measured: 0.0392 m, 0.322° (odometry 0.0356 m, 0.731°), 189 relations
    pytest.param("aces", 1200, 0.048, 0.40, None, id="aces-1200"),
    # measured: 0.0275 m, 0.382° (odometry 0.0461 m, 1.518°), 169 relations
    pytest.param("fr079", 800, 0.034, 0.48, None, id="fr079-800"),
]


def odometry_trajectory(log: Path, n_scans: int) -> Trajectory:
    """The odometry poses stored with the first ``n_scans`` laser scans (the relations' frame)."""
    scans = list(islice(iter_scans(log), n_scans))
    poses = [s.pose_odom_base if s.pose_odom_base is not None else s.pose_odom_laser for s in scans]
    return Trajectory.from_arrays([s.timestamp for s in scans], np.asarray(poses))


@pytest.mark.parametrize(("name", "scans", "max_trans_m", "max_rot_deg", "min_gain"), CASES)
def test_excerpt_relations_error_stays_within_its_bound(
    shared_data, tmp_path, monkeypatch, name, scans, max_trans_m, max_rot_deg, min_gain
):
    monkeypatch.setenv("LINESLAM_DATA", str(shared_data))
    resolved = resolve_log(name, root=shared_data)
    assert resolved.relations is not None
    summary = run_slam(name, tmp_path, RunConfig(), max_scans=scans)
    assert summary["scans"] == scans

    ours = read_tum(tmp_path / "trajectory.tum")
    relations = relations_within(read_relations(resolved.relations), ours.timestamps)
    assert len(relations) >= 50, "too few relations inside the excerpt to measure anything"
    metric = relations_metric(ours, relations)
    odometry = relations_metric(odometry_trajectory(resolved.log, scans), relations)
    print(
        f"{name}[:{scans}] {metric.n_used} relations: ours {metric.abs_trans_m} m, "
        f"{metric.abs_rot_deg} deg; odometry {odometry.abs_trans_m} m, {odometry.abs_rot_deg} deg"
    )
    assert metric.n_unmatched == 0
    assert metric.abs_trans_m.mean <= max_trans_m
    assert metric.abs_rot_deg.mean <= max_rot_deg
    if min_gain is not None:
        assert odometry.abs_trans_m.mean >= min_gain * metric.abs_trans_m.mean


def test_fr079_odometry_repaired_where_the_log_hides_reversing(shared_data):
    """fr079 logs reversing as forward motion; the odometry re-signed by the ODOM speed
    (``iter_log_scans(..., "velocity")``, the default) must agree with the short relations
    (< 5 s apart) far better than the logged one.  Measured 2026-11-29 on the first 1600
    scans (329 relations): logged 0.0729 ± 0.161 m, re-signed 0.0399 ± 0.031 m."""
    from dataclasses import fields

    from slam.io.carmen import iter_log_scans

    resolved = resolve_log("fr079", root=shared_data)
    assert resolved.relations is not None
    errors = {}
    for sign in ("logged", "velocity"):
        scans = list(islice(iter_log_scans(resolved.log, sign), 1600))
        poses = np.asarray([s.pose_odom_base for s in scans])
        odometry = Trajectory.from_arrays([s.timestamp for s in scans], poses)
        rel = relations_within(read_relations(resolved.relations), odometry.timestamps)
        short = (rel.t2 - rel.t1) < 5.0
        rel = type(rel)(**{f.name: getattr(rel, f.name)[short] for f in fields(rel)})
        assert len(rel) >= 300
        errors[sign] = relations_metric(odometry, rel).abs_trans_m.mean
    assert errors["velocity"] <= 0.05
    assert errors["velocity"] <= 0.7 * errors["logged"]


def _skip_unless_reference_kernels() -> None:
    """Skip where the BLAS kernels are not those of the documented figures (slam.blas).

    A setting that lets one wrong closure through is shown failing by that one decision; other
    kernels change the last bits of the arithmetic and can change the decision.
    """
    architectures = {lib["architecture"] for lib in kernels_in_use()["libraries"]}
    if architectures != {CORETYPE}:
        pytest.skip(f"one closure decision, reproduced with the {CORETYPE} kernels only")


def _variant_excerpt(name, config, max_scans, shared_data, tmp_path, monkeypatch):
    """A robustness row's log (``make_variant``) run for its first ``max_scans`` scans with
    ``config``; ``(relations inside the excerpt, relations metric on them)``."""
    from slam.experiments.robustness import make_variant, variant_by_name

    monkeypatch.setenv("LINESLAM_DATA", str(shared_data))
    files = make_variant(variant_by_name(name), tmp_path / "variants", root=shared_data)
    run_slam(files.log, tmp_path / "run", config, max_scans=max_scans)
    ours = read_tum(tmp_path / "run" / "trajectory.tum")
    relations = relations_within(read_relations(files.relations), ours.timestamps)
    return len(relations), relations_metric(ours, relations)


@pytest.mark.parametrize(
    ("spread", "within"), [("disagreement", True), ("slip", False)], ids=["default", "slip"]
)
def test_narrow_field_of_view_keeps_its_heading_through_a_turn_on_the_spot(
    shared_data, tmp_path, monkeypatch, spread, within
):
    """ACES with a 60° field of view (the ``aces-fov60`` robustness row), first 4,500 scans.

    At scans 3,320-3,334 the robot turns on the spot: two scan matches there contradict the
    odometry with too little overlap to be trusted, and each step is centred on its match.
    Spread only as far as the odometry's heading (the default ``contradicted_spread``), the
    run stays within 0.06 m and 1.2° of the relations (measured 0.0449 m, 0.94°); with the
    slip component's fixed 0.35 rad (``"slip"``) a single line paired with a wall at right
    angles turns the trajectory there (measured 0.69 m, 2.3°; docs/real-logs.md, Opt-in
    settings).  Both measured with ``between_keyframes = false``.
    """
    if not within:
        _skip_unless_reference_kernels()
    config = RunConfig()
    sm = replace(config.slam.frontend.scan_matching, contradicted_spread=spread)
    frontend = replace(config.slam.frontend, scan_matching=sm)
    config = replace(config, slam=replace(config.slam, frontend=frontend))
    n_relations, metric = _variant_excerpt(
        "aces-fov60", config, 4500, shared_data, tmp_path, monkeypatch
    )
    assert n_relations >= 500
    print(f"aces-fov60[:4500] {spread}: {metric.abs_trans_m} m, {metric.abs_rot_deg} deg")
    ok = metric.abs_trans_m.mean <= 0.06 and metric.abs_rot_deg.mean <= 1.2
    assert ok == within


@pytest.mark.parametrize(
    ("both_costs", "within"), [(True, True), (False, False)], ids=["default", "off"]
)
def test_narrow_field_of_view_rejects_a_wrong_closure_judged_alone(
    shared_data, tmp_path, monkeypatch, both_costs, within
):
    """Intel with a 60° field of view (the ``intel-fov60`` robustness row), first 10,000 scans.

    At keyframe 2,494 (scan 9,668) a hypothesis of three pairs that no other agrees with
    would move the robot 6.0 m; it is wrong (``scripts/closure_oracle.py`` against the Intel
    run).  Judged alone it must pass the judge's F test in both costs
    (``judge_alone_both_costs``, the default): its merge lowers the loop's χ² (F −499) but
    raises its robust cost (robust F 243), and it is rejected; the excerpt stays within
    0.07 m of the relations (measured 0.041 m).  With the χ² test alone it is accepted
    (measured 0.148 m; docs/real-logs.md, Opt-in settings).  Both measured with
    ``between_keyframes = false``.  The second case is skipped where its run accepts no
    closure judged alone whose robust F exceeds the limit and that moves the robot by metres:
    on the AMD EPYC machine the hypothesis does not arise in either case (0.038 and 0.037 m;
    the second accepts two closures of 0.09 and 0.22 m on the χ² test alone).
    """
    if not within:
        _skip_unless_reference_kernels()
    config = RunConfig()
    lc = replace(config.slam.loop_closure, judge_alone_both_costs=both_costs)
    config = replace(config, slam=replace(config.slam, loop_closure=lc))
    n_relations, metric = _variant_excerpt(
        "intel-fov60", config, 10_000, shared_data, tmp_path, monkeypatch
    )
    assert n_relations >= 2000
    print(f"intel-fov60[:10000] both costs {both_costs}: {metric.abs_trans_m} m")
    if not within:
        # the case needs the decision it shows: a closure judged alone that the χ² test
        # accepts and the robust cost would not, moving the robot by metres like the wrong
        # hypothesis above (other arithmetic may not present it; closures of a few
        # centimetres that pass the χ² test only are right ones)
        summary = json.loads((tmp_path / "run" / "summary.json").read_text())
        limit = config.slam.loop_closure.judge_max_f
        chi2_only = [
            a
            for a in summary["loop_closures_log"]
            if a.get("accepted")
            and a.get("agreeing_hypotheses") == 0
            and a.get("f_statistic_robust", 0.0) > limit
            and float(np.hypot(*a["correction"][:2])) > 1.0
        ]
        if not chi2_only:
            pytest.skip("no closure judged alone passed the χ² test only with this arithmetic")
    assert (metric.abs_trans_m.mean <= 0.07) == within
