"""The BLAS kernels of a run, selected so that its results do not depend on the CPU.

numpy and scipy call OpenBLAS for their matrix products and factorisations, and OpenBLAS picks
its kernels for the CPU it runs on when it is loaded (``SkylakeX`` on a CPU with AVX-512,
``Haswell`` or ``Zen`` on most others).  The kernels add in different orders, so the last bits of
a product differ from one CPU to another.  Over a log of thousands of scans such differences
change which loop closures pass, and with them the result: the whole Intel log gives 0.0185 m
against its relations with the ``Haswell`` kernels and 0.0207 m with the ``SkylakeX`` ones, the
same code on the same machine (``python scripts/bench_slam.py intel --relations`` against the
same command with ``LINESLAM_NATIVE_BLAS=1``, on a CPU with AVX-512).

Importing :mod:`slam` therefore selects OpenBLAS's ``Haswell`` kernels (:func:`select_kernels`)
when

* numpy is not loaded yet (OpenBLAS reads its kernel choice once, when it is loaded: import
  :mod:`slam` before numpy, as the ``lineslam`` command does);
* the CPU is x86-64 and has the instructions those kernels need (AVX2 and FMA, read from
  ``/proc/cpuinfo`` on Linux; elsewhere nothing is selected);
* ``OPENBLAS_CORETYPE`` is not set (a kernel set chosen by the user is kept) and
  ``LINESLAM_NATIVE_BLAS`` is not ``1`` (which keeps OpenBLAS's own choice).

numpy's own loops are compiled for several instruction sets and pick theirs when numpy is
imported; its AVX-512 loops round differently from its AVX2 ones.  The same machine, the same
code, the whole Intel log: 0.0193 m with numpy's AVX-512 loops and 0.0165 m with its AVX2 ones
(``NPY_DISABLE_CPU_FEATURES``; AMD EPYC with AVX-512).  Where the ``Haswell`` kernels are
selected, numpy's AVX-512 loops are therefore switched off too (:data:`NUMPY_DISABLED`, for
numpy 2.4 and later, whose loops carry those names; ``NPY_DISABLE_CPU_FEATURES`` set by the user
is kept), so that CPUs with and without AVX-512 run the same arithmetic.

A run's ``summary.json`` records what was loaded (:func:`kernels_in_use`).  This module must not
import numpy.
"""

from __future__ import annotations

import importlib
import os
import platform
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

#: The OpenBLAS kernel set selected on x86-64 CPUs that have AVX2 and FMA.
CORETYPE = "Haswell"

#: numpy's dispatched loops switched off with the ``Haswell`` kernels (numpy 2.4's names for
#: its AVX-512 targets; ``NPY_DISABLE_CPU_FEATURES``).
NUMPY_DISABLED = "X86_V4 AVX512_ICL AVX512_SPR"

#: The first numpy release whose dispatched loops have the names in :data:`NUMPY_DISABLED`.
NUMPY_NAMES_SINCE = (2, 4)

#: Instructions the ``Haswell`` kernels use (``/proc/cpuinfo`` flag names).
REQUIRED_FLAGS = frozenset({"avx2", "fma"})

_X86_64 = frozenset({"x86_64", "amd64"})

#: Why the kernels were or were not selected when :mod:`slam` was imported.
selection: str = "not attempted"

#: Whether numpy's AVX-512 loops were switched off when :mod:`slam` was imported, or why not.
numpy_selection: str = "not attempted"


def cpu_field(name: str, cpuinfo: Path = Path("/proc/cpuinfo")) -> str:
    """The field ``name`` of the first CPU in ``cpuinfo`` (e.g. ``"model name"``).

    "" where the file is unreadable or has no such field.
    """
    try:
        with cpuinfo.open(encoding="ascii", errors="replace") as f:
            for line in f:
                key, sep, value = line.partition(":")
                if sep and key.strip() == name:
                    return value.strip()
    except OSError:
        pass
    return ""


def cpu_flags(cpuinfo: Path = Path("/proc/cpuinfo")) -> frozenset[str]:
    """The instruction-set flags of the first CPU in ``cpuinfo``; empty where it is unreadable."""
    return frozenset(cpu_field("flags", cpuinfo).split())


def selection_reason(
    environ: Mapping[str, str],
    numpy_loaded: bool,
    machine: str,
    flags: frozenset[str],
) -> str:
    """Whether to select the ``Haswell`` kernels: ``"selected"``, or why not (a sentence).

    Parameters
    ----------
    environ
        The process environment (``OPENBLAS_CORETYPE``, ``LINESLAM_NATIVE_BLAS``).
    numpy_loaded
        numpy is already imported, and OpenBLAS with it.
    machine
        ``platform.machine()``.
    flags
        The CPU's instruction-set flags (:func:`cpu_flags`).
    """
    if environ.get("LINESLAM_NATIVE_BLAS", "") == "1":
        return "LINESLAM_NATIVE_BLAS=1 keeps OpenBLAS's own choice"
    if "OPENBLAS_CORETYPE" in environ:
        return f"OPENBLAS_CORETYPE={environ['OPENBLAS_CORETYPE']} was set before lineslam"
    if numpy_loaded:
        return "numpy was imported before slam, with OpenBLAS's own choice"
    if machine.lower() not in _X86_64:
        return f"not an x86-64 CPU ({machine})"
    missing = REQUIRED_FLAGS - flags
    if missing:
        return f"the CPU lacks {' and '.join(sorted(missing))} (or its flags are unreadable)"
    return "selected"


def numpy_version() -> tuple[int, int] | None:
    """The installed numpy's ``(major, minor)``, read without importing it; None if unknown."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        major, minor = version("numpy").split(".")[:2]
        return int(major), int(minor)
    except (PackageNotFoundError, ValueError):
        return None


def numpy_reason(environ: Mapping[str, str], numpy: tuple[int, int] | None) -> str:
    """Whether to switch numpy's AVX-512 loops off: ``"selected"``, or why not (a sentence).

    Asked only where the ``Haswell`` kernels are selected (:func:`selection_reason`).

    Parameters
    ----------
    environ
        The process environment (``NPY_DISABLE_CPU_FEATURES``).
    numpy
        numpy's ``(major, minor)`` (:func:`numpy_version`).
    """
    if "NPY_DISABLE_CPU_FEATURES" in environ:
        value = environ["NPY_DISABLE_CPU_FEATURES"]
        return f"NPY_DISABLE_CPU_FEATURES={value} was set before lineslam"
    if numpy is None or numpy < NUMPY_NAMES_SINCE:
        return "numpy before 2.4 names its loops differently; its own choice is kept"
    return "selected"


def select_kernels() -> str:
    """Select OpenBLAS's ``Haswell`` kernels where :func:`selection_reason` allows; the reason.

    Sets ``OPENBLAS_CORETYPE`` in this process's environment (child processes inherit it) and
    records the reason in :data:`selection`; with it ``NPY_DISABLE_CPU_FEATURES`` where
    :func:`numpy_reason` allows (the reason in :data:`numpy_selection`).
    """
    global selection, numpy_selection
    reason = selection_reason(
        os.environ,
        "numpy" in sys.modules,
        platform.machine(),
        cpu_flags() if sys.platform.startswith("linux") else frozenset(),
    )
    if reason == "selected":
        os.environ["OPENBLAS_CORETYPE"] = CORETYPE
        numpy_selection = numpy_reason(os.environ, numpy_version())
        if numpy_selection == "selected":
            os.environ["NPY_DISABLE_CPU_FEATURES"] = NUMPY_DISABLED
    else:
        numpy_selection = f"not with the BLAS kernels: {reason}"
    selection = reason
    return reason


def kernels_in_use() -> dict[str, Any]:
    """The BLAS libraries loaded and their kernels, for ``summary.json``.

    ``{"selection": ..., "libraries": [{"library", "architecture", "version"}, ...],
    "numpy_selection": ..., "numpy_loops": [...]}``, from threadpoolctl (one entry per BLAS
    library loaded, numpy's and scipy's OpenBLAS each) and numpy (the instruction sets of its
    dispatched loops that this run uses; empty where numpy does not say).
    """
    from threadpoolctl import threadpool_info

    libraries = [
        {
            "library": str(info.get("internal_api", "")),
            "architecture": str(info.get("architecture", "")),
            "version": str(info.get("version", "")),
        }
        for info in threadpool_info()
        if info.get("user_api") == "blas"
    ]
    try:
        umath = importlib.import_module("numpy._core._multiarray_umath")
    except ImportError:  # numpy before 2.0
        loops: list[str] = []
    else:
        features = getattr(umath, "__cpu_features__", {})
        loops = [str(n) for n in getattr(umath, "__cpu_dispatch__", ()) if features.get(n)]
    return {
        "selection": selection,
        "libraries": libraries,
        "numpy_selection": numpy_selection,
        "numpy_loops": loops,
    }
