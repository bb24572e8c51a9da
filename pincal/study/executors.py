"""Run picklable tasks in this process, in local worker processes or on a Dask cluster.

A task is any picklable object with a ``run()`` method (the study's are in
:mod:`pincal.study.tasks`); :func:`execute` returns the results in task
order whatever ran them, and reports progress through a ``progress(done, total)``
callback (the command line draws it: :mod:`pincal.cli.progress`).

Faults. A Dask worker that dies is replaced (a LocalCluster's nanny restarts it)
and the scheduler reruns its tasks, so the results are the same number for
number. When the scheduler is lost, or a local worker process dies, the run
stops with a one-line :class:`pincal.errors.PincalError`; given a
:class:`pincal.study.checkpoints.TaskStore`, every task finished until then is
kept and a rerun runs only the others.
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import sys
import threading
from collections.abc import Sequence
from concurrent.futures import CancelledError, ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager, nullcontext
from typing import Any

from pincal.errors import PincalError
from pincal.progress import Progress  # called after each finished task
from pincal.study.checkpoints import TaskStore

__all__ = ["default_workers", "fork_is_safe", "execute"]


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


def fork_is_safe() -> bool:
    """Whether worker processes may be forked from this one rather than started afresh.

    A forked worker starts at once with this process's imports (numpy, scipy,
    Pinocchio: ~0.6 s of CPU that a fresh ``spawn`` worker spends importing them
    again). A fork copies only the calling thread, though, so a lock another
    thread held would stay locked in the child: fork only while this process runs
    one Python thread (BLAS pools are native and re-created after a fork), and
    only on Linux (macOS system frameworks are not fork-safe; Windows has no fork).
    """
    return sys.platform.startswith("linux") and threading.active_count() == 1


#: The thread pool (threadpoolctl's internal API name) each variable of :data:`_SINGLE_THREADED_BLAS` sets.
_POOL_OF_VARIABLE = {"OMP_NUM_THREADS": "openmp", "OPENBLAS_NUM_THREADS": "openblas", "MKL_NUM_THREADS": "mkl"}


def _worker_with_one_blas_thread(unset: Sequence[str]) -> None:
    """Initializer of forked workers: one thread in each pool whose variable of
    :data:`_SINGLE_THREADED_BLAS` the user left unset (``unset``), as spawned workers get
    from the environment (a forked worker's libraries read it when this process loaded
    them); a pool whose variable the user set keeps the user's setting, as it would in a
    spawned worker."""
    from threadpoolctl import ThreadpoolController

    pools = [_POOL_OF_VARIABLE[name] for name in unset]
    if pools:
        ThreadpoolController().select(internal_api=pools).limit(limits=1)


def _unset_thread_variables() -> list[str]:
    """The variables of :data:`_SINGLE_THREADED_BLAS` the user has not set."""
    return [name for name in _SINGLE_THREADED_BLAS if name not in os.environ]


@contextmanager
def _single_threaded_blas():
    """Set :data:`_SINGLE_THREADED_BLAS` (unless the user set them) for the processes
    spawned inside the block; restore the environment afterwards."""
    unset = _unset_thread_variables()
    os.environ.update({name: _SINGLE_THREADED_BLAS[name] for name in unset})
    try:
        yield
    finally:
        for name in unset:
            os.environ.pop(name, None)


def _run_task(task) -> list[dict[str, Any]]:
    """Entry point of every executor (module level, hence picklable)."""
    return task.run()


class _Results:
    """The tasks' results by task index: those a store already holds, then each one as it arrives
    (kept in the store, counted, reported)."""

    def __init__(self, tasks: Sequence, store: TaskStore | None, report: Progress) -> None:
        self.tasks, self.store, self.report = tasks, store, report
        self.values: list = [None] * len(tasks)
        self.pending: list[int] = []
        for index, task in enumerate(tasks):
            stored = None if store is None else store.load(task)
            if stored is None:
                self.pending.append(index)
            else:
                self.values[index] = stored
        self.resumed = self.done = len(tasks) - len(self.pending)
        if self.resumed:
            report(self.done, len(tasks))

    def add(self, index: int, rows: list[dict[str, Any]]) -> None:
        self.values[index] = rows
        if self.store is not None:
            self.store.save(self.tasks[index], rows)
        self.done += 1
        self.report(self.done, len(self.tasks))

    def describe(self, executor: str) -> str:
        if not self.resumed:
            return executor
        return f"{executor}; {self.resumed} of {len(self.tasks)} tasks resumed from an interrupted run"

    def lost(self, what: str) -> PincalError:
        """The one-line error of an executor that died, saying how to go on."""
        kept = (f"the {self.done} finished are kept in {self.store.folder}: rerun the same command to resume"
                if self.store is not None else "rerun the study")
        return PincalError(f"{what} after {self.done} of {len(self.tasks)} study tasks; {kept}")


def execute(
    tasks: Sequence,
    workers: int | None = None,
    scheduler: Any = None,
    progress: Progress | None = None,
    store: TaskStore | None = None,
) -> tuple[list, str]:
    """Run ``task.run()`` for every task; results in task order, whatever the executor.

    Args:
        tasks: picklable objects with a ``run()`` method.
        workers: local worker processes (default: all cores; 1 runs in this
            process); with ``scheduler="local"``, the LocalCluster's processes.
        scheduler: None (local processes), a Dask scheduler address, ``"local"``
            (start a Dask LocalCluster) or a ``distributed.Client``.
        progress: called as ``progress(done, total)`` after each task (and once
            at the start with the tasks taken from ``store``).
        store: finished tasks of an interrupted run (reused), where each task
            finished now is kept (:mod:`pincal.study.checkpoints`).

    Returns:
        The results and a description of the executor.

    Raises:
        PincalError: the Dask scheduler or a worker process was lost for good
            (a Dask worker lost once is replaced and its tasks rerun).
    """
    results = _Results(tasks, store, progress or (lambda done, total: None))
    if scheduler is not None:
        description = _execute_dask(tasks, workers, scheduler, results)
        return results.values, results.describe(description)
    workers = default_workers() if workers is None else workers
    if workers < 1:
        raise PincalError(f"workers must be >= 1, got {workers}")
    if workers == 1:
        for index in results.pending:
            results.add(index, _run_task(tasks[index]))
        return results.values, results.describe("in-process")
    if fork_is_safe():
        unset = _unset_thread_variables()  # before the block below sets them
        pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("fork"),
                                   initializer=_worker_with_one_blas_thread, initargs=(unset,))
    else:
        pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"))
    try:
        with _single_threaded_blas():  # the (spawned) workers start while the tasks are submitted
            futures = {pool.submit(_run_task, tasks[index]): index for index in results.pending}
        for future in as_completed(futures):
            results.add(futures[future], future.result())
    except BrokenProcessPool:
        raise results.lost("a local worker process died (out of memory?)") from None
    finally:
        pool.shutdown(cancel_futures=True)
    return results.values, results.describe(f"{workers} local processes")


def _execute_dask(tasks: Sequence, workers: int | None, scheduler: Any, results: _Results) -> str:
    """Run the pending tasks on Dask; a lost worker's tasks are rerun by the scheduler (up to its
    ``distributed.scheduler.allowed-failures``); returns the description of the executor."""
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
    lost = False
    try:
        futures = client.map(_run_task, [tasks[index] for index in results.pending], pure=False)
        index_of = {future.key: index for future, index in zip(futures, results.pending)}
        for future in distributed.as_completed(futures):
            results.add(index_of[future.key], future.result())  # gathered one by one, placed by key
            future.release()
    except CancelledError:  # the client lost its scheduler and cancelled every future
        lost = True
        raise results.lost(f"lost the Dask scheduler ({description})") from None
    except distributed.KilledWorker as exc:
        raise results.lost(f"a task killed one Dask worker after another ({exc})") from None
    finally:
        # closing a client that lost its scheduler interrupts its reconnection, which Dask
        # logs as a traceback: the one-line error above says it all
        with _silenced("distributed.client") if lost else nullcontext():
            for resource in owned:
                resource.close()
    return description


@contextmanager
def _silenced(logger: str):
    """Drop the log records of ``logger`` inside the block."""
    log = logging.getLogger(logger)
    was = log.disabled
    log.disabled = True
    try:
        yield
    finally:
        log.disabled = was
