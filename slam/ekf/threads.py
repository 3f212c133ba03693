"""Limit BLAS threads while filtering.

The EKF's work per scan is a few rank-``2m`` products on an ``n × n`` covariance; on a small,
shared machine multi-threaded BLAS makes them slower, not faster (the first 600 Intel scans:
18.7 s with the default OpenBLAS threads, 2.3 s with one thread, on a 2-core machine with
other jobs running).  Runners wrap the filtering loop in
:func:`blas_threads` with ``EkfConfig.blas_threads``.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["blas_threads"]


@contextmanager
def blas_threads(n: int) -> Iterator[None]:
    """Run the block with at most ``n`` BLAS threads (``n <= 0``: leave the library default)."""
    if n <= 0:
        yield
        return
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=n, user_api="blas"):
        yield
