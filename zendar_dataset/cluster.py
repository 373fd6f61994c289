"""Independent tasks on a Dask cluster (``dask.distributed``): the commands' ``--scheduler``.

Without a scheduler nothing here runs and dask is not imported: the work stays in the calling
process or on :func:`zendar_dataset.worker_pool.run_in_workers`. With one,
:meth:`DaskCluster.connect` joins its scheduler (a clear error, before any output is touched, when
it does not answer), :meth:`DaskCluster.shared_directory` proves that every worker sees the output
directory, and :meth:`DaskCluster.run` hands out one task per free worker thread, as
``run_in_workers`` does with its processes.

Worker loss: a task whose worker dies (killed, out of memory, its node gone) is given to another
worker by the scheduler, up to its ``distributed.scheduler.allowed-failures`` times (default 3)
before the run fails with the caller's ``worker_died`` error. ``retries=`` is not used: it re-runs
tasks that *raised*, and a task that raised here is a real failure, which stops the run.

Temporaries: a worker writes under hidden temporary names carrying its process id
(:mod:`zendar_dataset.temporary_files`), which mean nothing on another host, so the host-local
staleness test alone could remove a live worker's temporary. :meth:`DaskCluster.remove_orphaned_temporaries`
also keeps every temporary whose process id is a live worker's.
"""

from __future__ import annotations

import contextlib
import logging
import os
import pathlib
import re
import secrets
import sys
import uuid
from collections import Counter
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import Any, TypeVar

from zendar_dataset.errors import ZendarError
from zendar_dataset.temporary_files import is_stale, owner_pid, remove_temporary, temporary_sibling
from zendar_dataset.worker_pool import usable_cpus

Task = TypeVar("Task")

#: The environment variable naming the scheduler when ``--scheduler`` is absent.
SCHEDULER_ENV = "ZENDAR_DASK_SCHEDULER"
#: How long a scheduler has to answer before the command gives up (exit status 1).
CONNECT_TIMEOUT_S = 10.0
#: How long to wait for a first worker on a scheduler that has none (a batch job still queued).
WORKER_WAIT_S = 300.0
#: How long Ctrl-C waits for the workers running its tasks to restart: a nanny kills a worker whose task
#: does not stop within seconds and starts a new one; a restart seen to take longer can leave temporaries,
#: kept while their process lives (the next run removes them).
RESTART_TIMEOUT_S = 10.0

_URL = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]*://")
_NO_MORE_TASKS = object()
_PROBE_NAME = "cluster-probe"
# The BLAS/OpenMP limits of this worker process, kept alive: they hold while the object exists.
_THREAD_LIMITS: Any = None
_THREAD_LIMIT = 0


class ClusterUnavailable(ConnectionError):
    """The scheduler does not answer, or no worker joined it (exit status 1, as any environment failure)."""


def scheduler_address(flag: str | None) -> str | None:
    """The scheduler to use: ``flag`` (``--scheduler``), else ``$ZENDAR_DASK_SCHEDULER``, else None (no cluster)."""
    address = flag if flag is not None else os.environ.get(SCHEDULER_ENV, "")
    return address.strip() or None


def refuse_url_output(location: str | os.PathLike, what: str) -> None:
    """Raise when ``location`` is a URL: the workers write it as a path, so it must be one they all mount.

    Raises
    ------
    ZendarError
        Naming ``what`` (``"OUT"``, ``"--data"``) and the URL.
    """
    if _URL.match(os.fspath(location)):
        raise ZendarError(
            f"{what} {os.fspath(location)!r} is a URL; with a Dask scheduler the output must be a directory on a "
            "filesystem every worker mounts at the same path (this machine's disk for a cluster on this machine; "
            "NFS, Lustre, GPFS, BeeGFS or CephFS across machines): see docs/cluster.md"
        )


@dataclass(frozen=True)
class SharedDirectory:
    """A directory the client and every worker see: a probe file there holds a token only this run knows.

    Attributes
    ----------
    directory : pathlib.Path
    probe : pathlib.Path
        The probe file, a hidden temporary of the client's (removed when the run ends; a stale one is
        removed like any temporary).
    token : str
        The probe's content.
    """

    directory: pathlib.Path
    probe: pathlib.Path
    token: str

    def problem_here(self) -> str | None:
        """Why this process does not see the directory the client wrote the probe in, or None when it does."""
        try:
            found = self.probe.read_text(encoding="utf-8")
        except OSError as exc:
            return f"cannot read {self.probe} ({type(exc).__name__}: {exc.strerror or exc})"
        return None if found == self.token else f"{self.probe} holds another run's probe (another filesystem at that path)"


def _which_workers(problems: dict[str, str], n_workers: int) -> str:
    """``the Dask worker W (why)`` or ``2 of the 5 Dask workers (W: why; ...)``, from address -> why."""
    if n_workers == 1:
        ((worker, problem),) = problems.items()
        return f"the Dask worker {worker} ({problem})"
    shown = "; ".join(f"{worker}: {problem}" for worker, problem in sorted(problems.items())[:3])
    more = f" (and {len(problems) - 3} more)" if len(problems) > 3 else ""
    return f"{len(problems)} of the {n_workers} Dask workers ({shown}{more})"


def _not_shared(directory: pathlib.Path, problems: dict[str, str], n_workers: int) -> ZendarError:
    """The error for workers that do not see ``directory``: ``problems`` maps each one's address to why."""
    return ZendarError(
        f"{directory} is not visible to {_which_workers(problems, n_workers)}; write to a directory on a filesystem "
        "every worker mounts at the same path: see docs/cluster.md"
    )


@contextlib.contextmanager
def _quiet_distributed_logs() -> Iterator[None]:
    # A refused connection makes distributed log a traceback; the command prints one line instead.
    logger = logging.getLogger("distributed")
    level = logger.level
    logger.setLevel(logging.CRITICAL + 1)
    try:
        yield
    finally:
        logger.setLevel(level)


class DaskCluster:
    """A connection to a Dask scheduler, and the runs of tasks on its workers.

    Use :meth:`connect`; close it (or use it as a context manager) when done.
    """

    def __init__(self, address: str, client: Any) -> None:
        self.address = address
        self.client = client

    @classmethod
    def connect(cls, address: str) -> DaskCluster:
        """Connect to the scheduler at ``address`` and wait until it has a worker.

        Parameters
        ----------
        address
            ``tcp://host:8786`` (or any address with a port that ``distributed.Client`` takes).

        Raises
        ------
        ClusterUnavailable
            The scheduler does not answer within :data:`CONNECT_TIMEOUT_S`, or no worker joined it
            within :data:`WORKER_WAIT_S`.
        ZendarError
            ``address`` is not an address.
        """
        from distributed import Client
        from distributed.comm import get_address_host_port

        try:
            get_address_host_port(address)
        except ValueError as exc:
            raise ZendarError(f"--scheduler / ${SCHEDULER_ENV}: {address!r} is not a scheduler address ({exc}); "
                              "expected e.g. tcp://host:8786") from None
        try:
            with _quiet_distributed_logs():
                client = Client(address, timeout=CONNECT_TIMEOUT_S, set_as_default=False)
        except OSError:  # TimeoutError included
            raise ClusterUnavailable(
                f"the Dask scheduler at {address} did not answer within {CONNECT_TIMEOUT_S:g} s; start it "
                f"(dask scheduler) or check --scheduler / ${SCHEDULER_ENV}"
            ) from None
        cluster = cls(address, client)
        try:
            if not client.nthreads():
                print(f"waiting up to {WORKER_WAIT_S:g} s for a worker to join the Dask scheduler at {address}",
                      file=sys.stderr, flush=True)
                client.wait_for_workers(1, timeout=WORKER_WAIT_S)
        except TimeoutError:
            cluster.close()
            raise ClusterUnavailable(f"the Dask scheduler at {address} has no worker (waited {WORKER_WAIT_S:g} s); "
                                     "start some (dask worker ADDRESS) and run again") from None
        except BaseException:
            cluster.close()
            raise
        return cluster

    def close(self) -> None:
        """Disconnect (the scheduler and its workers keep running)."""
        self.client.close()

    def __enter__(self) -> DaskCluster:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def live_worker_pids(self) -> set[int]:
        """The process ids of the workers connected now (on whichever hosts)."""
        return {pid for pid in self.client.run(os.getpid, on_error="ignore").values() if isinstance(pid, int)}

    def remove_orphaned_temporaries(self, directory: str | os.PathLike) -> list[pathlib.Path]:
        """Remove this package's temporaries in ``directory`` whose writer is gone from the cluster and from here.

        A temporary is kept while its process id is a live worker's (it may be running on another host,
        where this host's process table says nothing) or a live process's on this host.

        Returns
        -------
        list of pathlib.Path
            What was removed.
        """
        directory = pathlib.Path(directory)
        try:
            entries = [directory / entry.name for entry in os.scandir(directory) if entry.name.startswith(".")]
        except (FileNotFoundError, NotADirectoryError):
            return []
        try:
            live = self.live_worker_pids()
        except OSError:  # the scheduler is gone too: any temporary may still be a live worker's
            return []
        removed = []
        for path in entries:
            pid = owner_pid(path)
            if pid is not None and pid not in live and is_stale(path):
                remove_temporary(path)
                removed.append(path)
        return removed

    @contextlib.contextmanager
    def shared_directory(self, directory: str | os.PathLike) -> Iterator[SharedDirectory]:
        """Check that every worker sees ``directory`` (an existing one), for the duration of a run.

        The client writes a probe file with a random token in ``directory`` and every worker reads it
        back; the probe stays until the block ends, so that :meth:`run` checks it on workers that join
        later too.

        Raises
        ------
        ZendarError
            Naming the workers that do not see the directory and why.
        """
        directory = pathlib.Path(directory)
        probe = temporary_sibling(directory / _PROBE_NAME)
        shared = SharedDirectory(directory, probe, secrets.token_hex(16))
        try:
            with open(probe, "x", encoding="utf-8") as handle:
                handle.write(shared.token)
            answers = self.client.run(_problem_on_worker, shared, on_error="return")
            # An exception instead of an answer: the worker could not even run the check.
            failed = {worker: str(answer) for worker, answer in answers.items() if isinstance(answer, BaseException)}
            if failed:
                raise ZendarError(f"{_which_workers(failed, len(answers))} cannot run this package's code; install the "
                                  "same zendar-dataset as here on every worker (docs/cluster.md)")
            problems = {worker: answer for worker, answer in answers.items() if answer is not None}
            if problems:
                raise _not_shared(directory, problems, len(answers))
            yield shared
        finally:
            remove_temporary(probe)

    def run(
        self,
        function: Callable[[Task], Any],
        tasks: Iterable[Task],
        *,
        shared: SharedDirectory | None,
        on_done: Callable[[Task, Any], None],
        worker_died: Callable[[Task], BaseException],
        on_interrupt: Callable[[], None] | None = None,
    ) -> None:
        """Run ``function(task)`` for every task on the cluster's workers, one task per worker thread at a time.

        As :func:`zendar_dataset.worker_pool.run_in_workers`: ``function`` and the tasks must be
        picklable and importable on the workers; each result goes to ``on_done(task, result)`` here, in
        completion order; after a task fails no new one is started, the tasks in progress are
        finished, and the first failure is raised; a task the scheduler gave up on (its workers died
        ``allowed-failures + 1`` times) fails the run with ``worker_died(task)``. Each task first checks
        that its worker sees ``shared`` (the directory it writes to; None for tasks that only read and
        return their results) and caps its numba and BLAS threads to its share of its host's CPUs. On Ctrl-C or any other exception here, the queued tasks are cancelled, the
        workers running one are restarted through their nannies (stopping what they write; a worker
        without a nanny finishes its task), ``on_interrupt()`` runs, and the exception propagates.
        """
        from distributed import as_completed

        completions = as_completed(loop=self.client.loop)
        pending = iter(tasks)
        running: dict[Any, Task] = {}
        failure: BaseException | None = None
        name = getattr(function, "__name__", "task")
        try:
            while True:
                if failure is None:
                    worker_threads = self.client.nthreads()
                    capacity = max(1, sum(worker_threads.values()))
                    host_threads = _threads_per_host(worker_threads)
                    while len(running) < capacity:
                        task = next(pending, _NO_MORE_TASKS)
                        if task is _NO_MORE_TASKS:
                            break
                        future = self.client.submit(_run_on_worker, function, task, shared, host_threads,
                                                    key=f"{name}-{uuid.uuid4().hex}", pure=False)
                        running[future] = task
                        completions.add(future)
                if not running:
                    break
                finished = [(running.pop(future), future) for future in completions.next_batch(block=True)]
                # Every failure in the batch is seen before a new task is handed out (as run_in_workers).
                for task, future in finished:
                    if future.status != "finished":
                        failure = failure or _task_failure(future, task, worker_died)
                for task, future in finished:
                    if future.status == "finished":
                        on_done(task, future.result())
                    future.release()
        except BaseException:
            self._stop(list(running))
            if on_interrupt is not None:
                on_interrupt()
            raise
        if failure is not None:
            raise failure

    def _stop(self, futures: list[Any]) -> None:
        """Cancel ``futures`` and restart the workers running one of them."""
        if not futures:
            return
        keys = {future.key for future in futures}
        with contextlib.suppress(Exception):  # a scheduler gone as well: nothing left to stop through it
            busy = [worker for worker, processing in self.client.processing().items() if keys & set(processing)]
            self.client.cancel(futures, force=True)
            if busy:
                self.client.restart_workers(busy, timeout=RESTART_TIMEOUT_S, raise_for_error=False)


@contextlib.contextmanager
def connected(address: str | None) -> Iterator[DaskCluster | None]:
    """The cluster of the scheduler at ``address`` (:meth:`DaskCluster.connect`) for the block, or None
    without an address; disconnected when the block ends."""
    if address is None:
        yield None
        return
    with DaskCluster.connect(address) as cluster:
        yield cluster


def _threads_per_host(worker_threads: dict[str, int]) -> dict[str, int]:
    """Host -> the threads of the workers it runs, from worker address -> threads."""
    from distributed.comm import get_address_host

    hosts: Counter = Counter()
    for address, threads in worker_threads.items():
        hosts[get_address_host(address)] += threads
    return dict(hosts)


def _task_failure(future: Any, task: Any, worker_died: Callable[[Any], BaseException]) -> BaseException:
    from distributed import KilledWorker

    if future.status != "error":
        return worker_died(task)  # cancelled or lost by the cluster (a scheduler restart), not by this run
    error = future.exception()
    return worker_died(task) if isinstance(error, KilledWorker) else error


def _problem_on_worker(shared: SharedDirectory) -> str | None:
    """On a worker (``client.run``): why it does not see ``shared``, or None."""
    return shared.problem_here()


def _run_on_worker(function: Callable[[Task], Any], task: Task, shared: SharedDirectory | None,
                   host_threads: dict[str, int]) -> Any:
    """On a worker: check ``shared``, cap the threads to this worker's share of its host, run ``function(task)``."""
    import numba
    from distributed import get_worker
    from distributed.comm import get_address_host

    worker = get_worker()
    problem = None if shared is None else shared.problem_here()
    if problem is not None:
        raise _not_shared(shared.directory, {worker.address: problem}, 1)
    # A host not counted yet (its worker joined after the task was handed out): this worker's own threads.
    host = get_address_host(worker.address)
    threads = max(1, usable_cpus() // max(1, host_threads.get(host, worker.state.nthreads)))
    _limit_blas_threads(threads)
    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))  # per thread: this task's
    return function(task)


def _limit_blas_threads(threads: int) -> None:
    """Cap this worker process's BLAS/OpenMP threads (process-wide, so once per value)."""
    global _THREAD_LIMITS, _THREAD_LIMIT
    if _THREAD_LIMIT != threads:
        from threadpoolctl import threadpool_limits

        _THREAD_LIMITS = threadpool_limits(limits=threads)
        _THREAD_LIMIT = threads


__all__ = ["SCHEDULER_ENV", "ClusterUnavailable", "DaskCluster", "SharedDirectory", "connected", "refuse_url_output",
           "scheduler_address"]
