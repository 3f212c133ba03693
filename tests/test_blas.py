"""The BLAS kernels are selected so that a run's numbers do not depend on the CPU (slam.blas)."""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys

import pytest

import slam.blas
from slam.blas import (
    CORETYPE,
    NUMPY_DISABLED,
    cpu_flags,
    kernels_in_use,
    numpy_reason,
    selection_reason,
)

CAPABLE = frozenset({"sse2", "avx", "avx2", "fma", "avx512f"})


def test_selection_reason_known_answers():
    # a capable x86-64 CPU, nothing set, numpy not loaded yet: selected
    assert selection_reason({}, False, "x86_64", CAPABLE) == "selected"
    assert selection_reason({}, False, "AMD64", CAPABLE) == "selected"
    # the user's own choices win, and numpy loaded first is too late
    assert "OPENBLAS_CORETYPE=Zen" in selection_reason(
        {"OPENBLAS_CORETYPE": "Zen"}, False, "x86_64", CAPABLE
    )
    assert "LINESLAM_NATIVE_BLAS" in selection_reason(
        {"LINESLAM_NATIVE_BLAS": "1"}, False, "x86_64", CAPABLE
    )
    assert selection_reason({"LINESLAM_NATIVE_BLAS": "0"}, False, "x86_64", CAPABLE) == ("selected")
    assert "numpy was imported" in selection_reason({}, True, "x86_64", CAPABLE)
    # CPUs that cannot run the kernels
    assert "aarch64" in selection_reason({}, False, "aarch64", CAPABLE)
    assert "lacks avx2" in selection_reason({}, False, "x86_64", frozenset({"sse2", "fma"}))
    assert "lacks avx2 and fma" in selection_reason({}, False, "x86_64", frozenset())


def test_cpu_flags_reads_the_first_cpu(tmp_path):
    info = tmp_path / "cpuinfo"
    info.write_text(
        "processor\t: 0\nmodel name\t: X\nflags\t\t: fpu sse2 avx2 fma\n\n"
        "processor\t: 1\nflags\t\t: fpu\n"
    )
    assert cpu_flags(info) == frozenset({"fpu", "sse2", "avx2", "fma"})
    assert cpu_flags(tmp_path / "missing") == frozenset()
    (tmp_path / "noflags").write_text("processor\t: 0\n")
    assert cpu_flags(tmp_path / "noflags") == frozenset()


def test_the_tests_run_on_the_kernels_a_run_selects():
    # conftest imports slam before numpy, so the tests see what `lineslam` sees
    assert "numpy was imported" not in slam.blas.selection
    libraries = kernels_in_use()["libraries"]
    assert libraries
    # selected here, or inherited from the pytest process that started this worker
    if os.environ.get("OPENBLAS_CORETYPE") == CORETYPE:
        assert {lib["architecture"] for lib in libraries} == {CORETYPE}


def test_importing_slam_loads_no_numpy():
    code = "import sys, slam; print('numpy' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def _kernels_in_fresh_process(code: str, env: dict[str, str] | None = None) -> dict:
    out = subprocess.run(
        [
            sys.executable,
            "-c",
            code + "; import json, slam.blas, scipy.linalg; "
            "print(json.dumps(slam.blas.kernels_in_use()))",
        ],
        capture_output=True,
        text=True,
        check=True,
        env=env,
    )
    return json.loads(out.stdout)


CAN_SELECT = selection_reason({}, False, platform.machine(), cpu_flags())


@pytest.mark.skipif(CAN_SELECT != "selected", reason=CAN_SELECT)
def test_import_order_decides_the_kernels():
    env = {
        k: v
        for k, v in os.environ.items()
        if k not in ("OPENBLAS_CORETYPE", "NPY_DISABLE_CPU_FEATURES")
    }
    first = _kernels_in_fresh_process("import slam, numpy", env)
    assert first["selection"] == "selected"
    assert {lib["architecture"] for lib in first["libraries"]} == {CORETYPE}
    late = _kernels_in_fresh_process("import numpy, slam", env)
    assert "numpy was imported" in late["selection"]
    native = _kernels_in_fresh_process("import slam", {**env, "LINESLAM_NATIVE_BLAS": "1"})
    assert "LINESLAM_NATIVE_BLAS" in native["selection"]


def test_numpy_reason_known_answers():
    assert numpy_reason({}, (2, 4)) == "selected"
    assert numpy_reason({}, (3, 0)) == "selected"
    # older numpy names its loops differently; an unknown version is left alone
    assert "before 2.4" in numpy_reason({}, (2, 3))
    assert "before 2.4" in numpy_reason({}, None)
    # the user's own choice wins
    assert "NPY_DISABLE_CPU_FEATURES=AVX2" in numpy_reason(
        {"NPY_DISABLE_CPU_FEATURES": "AVX2"}, (2, 4)
    )


@pytest.mark.skipif(CAN_SELECT != "selected", reason=CAN_SELECT)
def test_numpy_avx512_loops_are_off_with_the_kernels():
    env = {
        k: v
        for k, v in os.environ.items()
        if k not in ("OPENBLAS_CORETYPE", "NPY_DISABLE_CPU_FEATURES", "LINESLAM_NATIVE_BLAS")
    }
    run = _kernels_in_fresh_process("import slam, numpy", env)
    if run["numpy_selection"] != "selected":
        pytest.skip(run["numpy_selection"])
    # none of the switched-off instruction sets is used, whatever the CPU has
    assert run["numpy_loops"]
    assert not set(run["numpy_loops"]) & set(NUMPY_DISABLED.split())
    # with the native choice numpy keeps every loop the CPU can run
    native = _kernels_in_fresh_process("import slam", {**env, "LINESLAM_NATIVE_BLAS": "1"})
    assert "LINESLAM_NATIVE_BLAS" in native["numpy_selection"]
    assert set(native["numpy_loops"]) >= set(run["numpy_loops"])
    if "avx512f" in cpu_flags() and "avx512bw" in cpu_flags():
        assert set(native["numpy_loops"]) & set(NUMPY_DISABLED.split())
