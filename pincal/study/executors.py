"""Run picklable tasks in this process, in local worker processes or on a Dask cluster.

A task is any picklable object with a ``run()`` method (the study's are in
:mod:`pincal.study.tasks`); :func:`execute` returns the results in task
order whatever ran them, and reports progress through a ``progress(done, total)``
callback (the command line draws it: :mod:`pincal.cli.progress`).
"""

from __future__ import annotations

import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor, as_completed
from contextlib import contextmanager
from typing import Any, Callable, Sequence

from pincal.errors import PincalError

#: ``progress(done, total)``, called after each finished task.
Progress = Callable[[int, int], None]


def default_workers() -> int:
    """All cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


#: Worker processes use one BLAS thread each: the parallelism is across tasks, and
#: several multi-threaded BLAS pools on the same cores slow every task down (Dask's
#: nanny sets the same variables for its worker processes).
_SINGLE_THREADED_BLAS = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


@contextmanager
def _single_threaded_blas():
    """Set :data:`_SINGLE_THREADED_BLAS` (unless the user set them) for the processes
    spawned inside the block; restore the environment afterwards."""
    unset = [name for name in _SINGLE_THREADED_BLAS if name not in os.environ]
    os.environ.update({name: _SINGLE_THREADED_BLAS[name] for name in unset})
    try:
        yield
    finally:
        for name in unset:
            os.environ.pop(name, None)


def _run_task(task) -> list[dict[str, Any]]:
    """Entry point of every executor (module level, hence picklable)."""
    return task.run()


def execute(
    tasks: Sequence, workers: int | None = None, scheduler: Any = None, progress: Progress | None = None
) -> tuple[list, str]:
    """Run ``task.run()`` for every task; results in task order, whatever the executor.

    Args:
        tasks: picklable objects with a ``run()`` method.
        workers: local worker processes (default: all cores; 1 runs in this
            process); with ``scheduler="local"``, the LocalCluster's processes.
        scheduler: None (local processes), a Dask scheduler address, ``"local"``
            (start a Dask LocalCluster) or a ``distributed.Client``.
        progress: called as ``progress(done, total)`` after each task.

    Returns:
        The results and a description of the executor.
    """
    report = progress or (lambda done, total: None)
    if scheduler is not None:
        return _execute_dask(tasks, workers, scheduler, report)
    workers = default_workers() if workers is None else workers
    if workers < 1:
        raise PincalError(f"workers must be >= 1, got {workers}")
    results: list = [None] * len(tasks)
    if workers == 1:
        for index, task in enumerate(tasks):
            results[index] = _run_task(task)
            report(index + 1, len(tasks))
        return results, "in-process"
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"))
    try:
        with _single_threaded_blas():  # the workers start while the tasks are submitted
            futures = {pool.submit(_run_task, task): index for index, task in enumerate(tasks)}
        for done, future in enumerate(as_completed(futures), start=1):
            results[futures[future]] = future.result()
            report(done, len(tasks))
    finally:
        pool.shutdown(cancel_futures=True)
    return results, f"{workers} local processes"


def _execute_dask(tasks: Sequence, workers: int | None, scheduler: Any, report: Progress) -> tuple[list, str]:
    try:
        import distributed
    except ImportError:
        raise PincalError("--scheduler needs Dask: pip install 'dask[distributed]' (or 'pincal[dask]')") from None
    owned: list = []  # what this function started and must close, client first
    if scheduler == "local":
        n = default_workers() if workers is None else workers
        cluster = distributed.LocalCluster(n_workers=n, threads_per_worker=1, dashboard_address=None)
        client = distributed.Client(cluster)
        owned += [client, cluster]
        description = f"Dask LocalCluster ({n} processes)"
    elif isinstance(scheduler, str):
        try:
            client = distributed.Client(scheduler)
        except (OSError, TimeoutError, ValueError) as exc:
            raise PincalError(f"cannot reach the Dask scheduler at {scheduler}: {exc}") from None
        owned.append(client)
        description = f"Dask cluster at {scheduler}"
    else:
        client = scheduler
        description = f"Dask client of {client.scheduler.address}"
    try:
        futures = client.map(_run_task, list(tasks), pure=False)
        for done, _ in enumerate(distributed.as_completed(futures), start=1):
            report(done, len(futures))
        return list(client.gather(futures)), description
    finally:
        for resource in owned:
            resource.close()
