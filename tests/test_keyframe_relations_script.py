"""scripts/keyframe_relations.py on a demo run with keyframes farther apart than its scans."""

from __future__ import annotations

import re
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest

from slam.config import RunConfig
from slam.evaluation.relations_metric import relations_metric
from slam.io.relations import read_relations
from slam.io.tum import read_tum
from slam.runner import run_slam

ROOT = Path(__file__).resolve().parents[1]
DEMO = ROOT / "datasets" / "sim" / "demo"


def test_groups_partition_the_relations_and_the_whole_is_the_metric(tmp_path):
    cfg = RunConfig()
    keyframes = replace(cfg.slam.keyframes, min_distance_m=0.6, min_angle_rad=0.45)
    cfg = replace(cfg, slam=replace(cfg.slam, keyframes=keyframes))
    out = tmp_path / "run"
    summary = run_slam(DEMO / "log.clf", out, cfg)
    assert summary["keyframes"] < summary["scans"]
    text = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "keyframe_relations.py"), str(out)]
        + ["--relations", str(DEMO / "relations.txt")],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    rows = {
        name: (int(n), float(m))
        for name, n, m in re.findall(
            r"  (\w[\w ]*?)\s+(\d+)  mean translation error ([\d.]+) m", text
        )
    }
    both, neither, mixed, whole = (
        rows[k] for k in ("both keyframes", "neither a keyframe", "one of each", "all")
    )
    assert both[0] > 0 and neither[0] > 0 and mixed[0] > 0
    assert (
        both[0] + neither[0] + mixed[0]
        == whole[0]
        == len(read_relations(DEMO / "relations.txt").t1)
    )
    metric = relations_metric(
        read_tum(out / "trajectory.tum"), read_relations(DEMO / "relations.txt")
    )
    assert whole[1] == pytest.approx(metric.abs_trans_m.mean, abs=1e-4)
    mean_of_groups = (both[0] * both[1] + neither[0] * neither[1] + mixed[0] * mixed[1]) / whole[0]
    assert mean_of_groups == pytest.approx(whole[1], abs=2e-4)
