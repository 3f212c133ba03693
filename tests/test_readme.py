"""The README's Python example runs as printed and writes the files it promises."""

from __future__ import annotations

import json
import re

import numpy as np
from conftest import REPO_ROOT

from slam.io import read_tum


def first_python_block(markdown: str) -> str:
    """The code of the first ```python block of a Markdown text."""
    match = re.search(r"^```python\n(.*?)^```", markdown, flags=re.MULTILINE | re.DOTALL)
    assert match is not None, "README.md has no ```python block"
    return match.group(1)


def test_readme_python_example_runs_as_printed(tmp_path, monkeypatch, capsys):
    code = first_python_block((REPO_ROOT / "README.md").read_text(encoding="utf-8"))
    # The example names the demo log relative to the repository root and writes "out"
    # relative to the working directory: run it in a fresh folder that sees the datasets.
    (tmp_path / "datasets").symlink_to(REPO_ROOT / "datasets", target_is_directory=True)
    monkeypatch.chdir(tmp_path)
    exec(compile(code, "README.md", "exec"), {"__name__": "__readme__"})

    out = tmp_path / "out"
    for name in ("trajectory.tum", "map.json", "summary.json"):
        assert (out / name).is_file(), name
    trajectory = read_tum(out / "trajectory.tum")
    n_scans = sum(
        1 for line in (REPO_ROOT / "datasets/sim/demo/log.clf").open() if line.startswith("FLASER")
    )
    assert len(trajectory.timestamps) == n_scans
    assert np.isfinite(trajectory.poses).all()
    lines = json.loads((out / "map.json").read_text())["lines"]
    assert len(lines) > 0
    assert json.loads((out / "summary.json").read_text())["scans"] == n_scans
    assert "poses," in capsys.readouterr().out
