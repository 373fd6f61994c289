"""Independent tasks on spawned worker processes: one task per free worker, threads capped per worker.

The simulator's scenes (``zendar-data synth --jobs``) and ``zendar-bench``'s CNN seeds run here.
Workers are spawned, not forked: a forked child of a process whose OpenMP, BLAS or torch thread pools
have run can deadlock. Each worker caps numba's, BLAS/OpenMP's and torch's threads, so ``jobs``
workers of ``threads`` threads fill the CPUs without oversubscribing them, keeps the memory it frees
for reuse (:mod:`zendar_dataset.freed_memory`), and leaves Ctrl-C to the parent, which stops every
worker at once.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import sys
from collections.abc import Callable, Iterable
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Any, TypeVar

from zendar_dataset.freed_memory import keep_freed_memory

Task = TypeVar("Task")

_THREAD_LIMITS = None
_NO_MORE_TASKS = object()


def usable_cpus() -> int:
    """CPUs this process may run on (its affinity mask, not the machine's count)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # no affinity API (macOS, Windows)
        return os.cpu_count() or 1


def _init_worker(threads: int) -> None:
    """Worker set-up: Ctrl-C left to the parent, freed memory kept for reuse, numba, BLAS/OpenMP and
    torch threads capped."""
    global _THREAD_LIMITS
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    keep_freed_memory()
    import numba
    from threadpoolctl import threadpool_limits

    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    _THREAD_LIMITS = threadpool_limits(limits=threads)  # kept alive: the limits hold while it exists
    # torch takes its default thread count from OMP_NUM_THREADS when it loads (after this, with the
    # first task that needs it); importing it here would cost workers that never use it ~2 s.
    os.environ["OMP_NUM_THREADS"] = str(threads)
    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(threads)


def run_in_workers(
    function: Callable[[Task], Any],
    tasks: Iterable[Task],
    jobs: int,
    threads: int,
    *,
    on_done: Callable[[Task, Any], None],
    worker_died: Callable[[Task], BaseException],
    on_interrupt: Callable[[], None] | None = None,
) -> None:
    """Run ``function(task)`` for every task on ``jobs`` spawned processes of ``threads`` threads each.

    ``function`` and the tasks must be picklable (a module-level function, dataclass tasks). Each
    finished task's result goes to ``on_done(task, result)`` in this process, in completion order.
    After a task fails no new one is started, the tasks in progress are finished, and the first
    failure is raised. A worker that dies (killed, out of memory) fails the run with
    ``worker_died(task)`` (a ``ProcessPoolExecutor`` is broken by a dead worker, where a
    ``multiprocessing.Pool`` would start replacements for ever). On Ctrl-C or any other exception
    here, every worker is stopped at once and ``on_interrupt()`` runs (to remove what they left half
    written) before the exception propagates.
    """
    executor = ProcessPoolExecutor(
        jobs, mp_context=multiprocessing.get_context("spawn"), initializer=_init_worker, initargs=(threads,)
    )
    try:
        pending = iter(tasks)
        running: dict[Future, Any] = {}
        failure: BaseException | None = None
        while True:
            while failure is None and len(running) < jobs:
                task = next(pending, _NO_MORE_TASKS)
                if task is _NO_MORE_TASKS:
                    break
                running[executor.submit(function, task)] = task
            if not running:
                break
            done, _ = wait(running, return_when=FIRST_COMPLETED)
            finished = [(running.pop(future), future) for future in done]
            # Every failure in the batch is seen before a new task is handed out: ``done`` is a set,
            # and a success read before a failure beside it would start a task after the failure.
            for task, future in finished:
                error = future.exception()
                if isinstance(error, BrokenProcessPool):
                    error = worker_died(task)
                if error is not None:
                    failure = failure or error
            for task, future in finished:
                if future.exception() is None:
                    on_done(task, future.result())
        executor.shutdown(wait=True)
    except BaseException:
        _terminate(executor)
        if on_interrupt is not None:
            on_interrupt()
        raise
    if failure is not None:
        raise failure


def _terminate(executor: ProcessPoolExecutor) -> None:
    """Stop ``executor``'s workers now, without waiting for their tasks."""
    # The executor has no public way before 3.14 to stop running workers, and 3.14's
    # ``terminate_workers`` does not wait for them; the caller then removes the workers' temporaries,
    # which counts only as stale once their processes are gone: terminate and join through the table.
    processes = list((executor._processes or {}).values())
    for process in processes:
        process.terminate()
    for process in processes:
        process.join()
    executor.shutdown(wait=True, cancel_futures=True)


__all__ = ["run_in_workers", "usable_cpus"]
