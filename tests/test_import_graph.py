"""Layering: linefit and the algorithmic parts of slam import no plotting or CLI code."""

from __future__ import annotations

import subprocess
import sys

import pytest

FORBIDDEN_FOR_LINEFIT = ["gtsam", "filterpy", "matplotlib", "typer", "click", "tqdm", "slam"]
FORBIDDEN_FOR_ALGORITHMS = [
    "matplotlib",
    "typer",
    "click",
    "tqdm",
    "slam.cli",
    "slam.plotting",
    "slam.plotting_scan",
]

# Algorithmic modules of slam; a module listed here that does not exist yet is skipped.
SLAM_ALGORITHM_MODULES = [
    "slam.geometry",
    "slam.types",
    "slam.lines",
    "slam.io",
    "slam.sim",
    "slam.evaluation",
    "slam.graph",
    "slam.ekf",
    "slam.frontend",
]


def imported_modules(module: str) -> set[str]:
    code = (
        f"import sys, importlib; importlib.import_module({module!r}); "
        "print('\\n'.join(sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return set(out.stdout.split())


def test_linefit_imports_none_of_the_heavy_or_upper_layers():
    mods = imported_modules("linefit")
    for name in FORBIDDEN_FOR_LINEFIT:
        assert not any(m == name or m.startswith(name + ".") for m in mods), name


@pytest.mark.parametrize("module", SLAM_ALGORITHM_MODULES)
def test_slam_algorithms_import_no_plotting_or_cli(module):
    import importlib.util

    if importlib.util.find_spec(module) is None:
        pytest.skip(f"{module} not present")
    mods = imported_modules(module)
    for name in FORBIDDEN_FOR_ALGORITHMS:
        assert not any(m == name or m.startswith(name + ".") for m in mods), (module, name)
