"""Run independent tasks serially, on a local process pool, or on a Dask cluster.

One code path for the parallel cases: :func:`map_tasks` always goes through
``dask.distributed`` — a ``LocalCluster`` of worker processes for ``workers > 1``, or the
scheduler at ``dask_address`` (``--dask tcp://host:8786``).  ``workers <= 1`` without an address
runs in this process (no Dask at all), which is also the reference the parallel runs must equal.

Determinism: tasks carry everything they need, their seeds included (derive them with
:func:`task_seed`), and results come back in task order, so a run gives the same numbers
serially, on a process pool, or on a cluster.

Interruption: the waiting checks for a signal (:func:`slam.interrupts.check`) between tasks
(serially) or every :data:`POLL_S` seconds (on a cluster).  When it is interrupted
(:class:`~slam.interrupts.Interrupted`, or a ``KeyboardInterrupt``), the tasks not finished are
cancelled and the local cluster's worker processes are killed at once (their tasks are lost
anyway), so that the run stops within a second or two, without Dask's shutdown warnings; the
exception then propagates.
"""

from __future__ import annotations

import logging
import os
import signal
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager, suppress
from typing import Any, TypeVar

import numpy as np

from slam import interrupts
from slam.errors import ConfigError

__all__ = ["map_tasks", "task_seed"]

POLL_S = 0.05
"""How often (s) the wait for a cluster's results checks for a signal."""

_GIVE_UP_S = 5.0
"""How long (s) an interrupted start or close of a cluster may take once its workers are killed."""

T = TypeVar("T")
R = TypeVar("R")


def task_seed(base_seed: int, *keys: int) -> int:
    """A seed for one task from the run's seed and the task's integer keys (stable, 63-bit)."""
    ss = np.random.SeedSequence([int(base_seed), *(int(k) for k in keys)])
    return int(
        ss.generate_state(2, dtype=np.uint32).astype(np.uint64)
        @ np.array([1 << 31, 1], dtype=np.uint64)
    )


@contextmanager
def _client(workers: int, dask_address: str | None, timeout_s: float) -> Iterator[Any]:
    """A Dask client (and the local cluster it runs on); closed, or killed when interrupted.

    Starting and closing a cluster take a second or two: they run in a helper thread
    (:func:`slam.interrupts.call_in_thread`), so that a signal meanwhile stops the run at once;
    the worker processes are then killed (and end anyway with this process: Dask's workers
    watch their parent).
    """
    with interrupts.at_once():  # importing: nothing to clean up
        try:
            from dask.distributed import Client, LocalCluster
        except ImportError as exc:  # pragma: no cover - depends on the installation
            raise ConfigError(
                "parallel runs need dask.distributed: pip install 'lineslam[dask]'"
            ) from exc
    if dask_address is not None:
        try:
            client = interrupts.call_in_thread(
                lambda: Client(dask_address, timeout=f"{timeout_s}s"), name="dask-connect"
            )
        except OSError as exc:
            raise ConfigError(f"cannot reach the Dask scheduler at {dask_address}: {exc}") from exc
        try:
            yield client
        finally:
            client.close()
        return
    # single-threaded BLAS in the workers: the tasks are many small problems
    saved = {v: os.environ.get(v) for v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")}
    for v in saved:
        os.environ[v] = "1"
    try:
        cluster = interrupts.call_in_thread(
            lambda: LocalCluster(
                n_workers=workers,
                threads_per_worker=1,
                processes=True,
                dashboard_address=":0",  # the scheduler always serves HTTP; any free port
            ),
            name="dask-start",
        )
    except BaseException as exc:
        if not isinstance(exc, Exception):  # interrupted while the workers start
            _mute_dask()
            _kill_children_until_stopped()  # the start then fails at once
        raise
    finally:
        for v, old in saved.items():
            if old is None:
                os.environ.pop(v, None)
            else:
                os.environ[v] = old
    client = Client(cluster)
    interrupted = False
    try:
        yield client
    except BaseException as exc:
        if not isinstance(exc, Exception):  # interrupted: no graceful shutdown
            interrupted = True
            _mute_dask()
            _kill_workers(cluster)
        raise
    finally:
        if interrupted:
            _close(client, cluster)  # quick: the workers are gone
        else:
            try:
                interrupts.call_in_thread(lambda: _close(client, cluster), name="dask-close")
            except BaseException as exc:
                if not isinstance(exc, Exception):  # interrupted while closing
                    interrupted = True
                    _mute_dask()
                    _kill_children_until_stopped()
                raise
            _unmute_dask()


def _close(client: Any, cluster: Any) -> None:
    client.close()
    cluster.close()


def _kill_children_until_stopped() -> None:
    """Kill this process's worker processes until the interrupted start or close has ended.

    The call left running (:func:`slam.interrupts.call_in_thread`) then fails or ends at once;
    waiting for it lets the process end normally (multiprocessing's resources released).
    Workers started meanwhile are killed too; after :data:`_GIVE_UP_S` the call is left.
    """
    import multiprocessing

    deadline = time.monotonic() + _GIVE_UP_S
    while True:
        for child in multiprocessing.active_children():
            with suppress(OSError):
                child.kill()
        if interrupts.wait_abandoned(POLL_S) or time.monotonic() > deadline:
            return


_MUTED: dict[str, int] = {}


def _mute_dask() -> None:
    """Silence Dask's warnings about tasks and workers stopped on purpose."""
    for name in ("distributed", "tornado"):
        log = logging.getLogger(name)
        _MUTED.setdefault(name, log.level)
        log.setLevel(logging.CRITICAL)


def _unmute_dask() -> None:
    while _MUTED:
        name, level = _MUTED.popitem()
        logging.getLogger(name).setLevel(level)


def _kill_workers(cluster: Any) -> None:
    """Kill a local cluster's worker processes (their tasks are abandoned)."""
    for nanny in list(getattr(cluster, "workers", {}).values()):
        process = getattr(getattr(nanny, "process", None), "process", None)
        pid = getattr(process, "pid", None)
        if isinstance(pid, int) and pid > 0:
            with suppress(OSError):
                os.kill(pid, signal.SIGKILL)


def map_tasks(
    fn: Callable[[T], R],
    tasks: Sequence[T],
    workers: int = 1,
    dask_address: str | None = None,
    progress: Callable[[int, int], None] | None = None,
    connect_timeout_s: float = 20.0,
) -> list[R]:
    """Apply ``fn`` to every task and return the results in task order.

    Parameters
    ----------
    fn : callable
        A module-level function (it is pickled to the workers).
    tasks : sequence
        Picklable task descriptions.
    workers : int
        ``<= 1``: run here, serially.  ``> 1``: a local Dask cluster of that many processes.
    dask_address : str, optional
        Address of a running Dask scheduler; overrides ``workers``.
    progress : callable, optional
        Called as ``progress(done, total)`` after each finished task.
    connect_timeout_s : float
        How long to wait for the scheduler at ``dask_address``.

    Returns
    -------
    list
        ``[fn(t) for t in tasks]``.
    """
    total = len(tasks)
    if dask_address is None and workers <= 1:
        out = []
        for i, task in enumerate(tasks):
            interrupts.check()
            out.append(fn(task))
            if progress is not None:
                progress(i + 1, total)
        return out
    from dask.distributed import as_completed

    with _client(workers, dask_address, connect_timeout_s) as client:
        futures = client.map(fn, list(tasks), pure=False)
        index = {f.key: i for i, f in enumerate(futures)}
        results: list[Any] = [None] * total
        try:
            waiting = as_completed(futures)
            done = 0
            while not waiting.is_empty():
                interrupts.check()
                if not waiting.has_ready():
                    time.sleep(POLL_S)
                    continue
                for future in waiting.next_batch(block=False):
                    results[index[future.key]] = future.result()
                    done += 1
                    if progress is not None:
                        progress(done, total)
        except BaseException as exc:
            if not isinstance(exc, Exception):  # interrupted: drop the tasks not finished
                _mute_dask()
                with suppress(Exception):
                    client.cancel(futures, force=True)
            raise
    return results
