"""Shared test fixtures: seeded RNGs and the location of the public logs."""

from __future__ import annotations

import os
from pathlib import Path

import slam  # noqa: F401  # isort: skip  (before numpy: selects the BLAS kernels, slam.blas)
import numpy as np
import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]


def data_root() -> Path:
    """``$LINESLAM_DATA`` if set, else ``../shared/datasets`` beside the repository."""
    env = os.environ.get("LINESLAM_DATA")
    return Path(env) if env else (REPO_ROOT.parent / "shared" / "datasets")


@pytest.fixture
def rng() -> np.random.Generator:
    """A fixed-seed generator, fresh for every test."""
    return np.random.default_rng(20030514)


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """Path to the public logs; skips (with the reason) where they are not present."""
    root = data_root()
    if not (root / "intel" / "intel.clf").is_file():
        pytest.skip(f"public logs not found under {root} (set LINESLAM_DATA)")
    return root
