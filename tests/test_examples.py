"""The examples run and their estimates agree with the truth they were simulated from."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2

gtsam = pytest.importorskip("gtsam")

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "line_landmark_graph.py"


def load_example():
    spec = importlib.util.spec_from_file_location("line_landmark_graph", EXAMPLE)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("seed", [20030514, 1, 2])
def test_line_landmark_graph_recovers_the_truth_within_its_marginals(seed):
    ex = load_example()
    out = ex.main(seed=seed, verbose=False)
    graph, result, marginals = out["graph"], out["result"], out["marginals"]
    X, L = gtsam.symbol_shorthand.X, gtsam.symbol_shorthand.L

    # converged: far below the start, and the residual is what the noise explains
    # (2 × error is χ² with (3 + 3·3 + 16·2) − (4·3 + 4·2) = 24 degrees of freedom)
    assert out["final_error"] < 1e-2 * out["initial_error"]
    assert 2.0 * out["final_error"] < chi2.ppf(0.999, 24)
    assert graph.size() == 1 + 3 + 16

    for i, truth in enumerate(ex.TRUE_POSES, start=1):
        cov = marginals.marginalCovariance(X(i))
        d = gtsam.Pose2.Logmap(truth.between(result.atPose2(X(i))))
        assert d @ np.linalg.solve(cov, d) < chi2.ppf(0.999, 3), (i, d)
        # the walls, not the poor odometry (σ 0.2 m, 0.1 rad per step), fix the poses
        assert np.all(np.sqrt(np.diag(cov)) < [0.05, 0.05, 0.02]), (i, cov)

    for j, wall in enumerate(ex.WALLS, start=1):
        cov = marginals.marginalCovariance(L(j))
        rho, phi = np.asarray(result.atPoint2(L(j)))
        d = np.array([rho - 0.0, np.angle(np.exp(1j * (phi - wall[1])))])  # truth: ρ = 0, φ = α
        assert d @ np.linalg.solve(cov, d) < chi2.ppf(0.999, 2), (j, d)


def test_line_landmark_graph_runs_as_a_script():
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
    }
    out = subprocess.run(
        [sys.executable, str(EXAMPLE)], capture_output=True, text=True, env=env, check=False
    )
    assert out.returncode == 0, out.stderr
    assert "20 factors" in out.stdout
    assert all(f"X{i} = " in out.stdout for i in range(1, 5))
    assert all(f"L{j}: (r, α)" in out.stdout for j in range(1, 5))
