"""Tasks on spawned worker processes: every result reaches the parent, the first failure stops the
run, and a worker that dies is named, not waited on for ever."""

from __future__ import annotations

import math
import os
import time
from pathlib import Path

import pytest

from zendar_dataset.errors import ZendarError
from zendar_dataset.worker_pool import run_in_workers, usable_cpus


def test_every_task_runs_once_and_its_result_comes_back():
    done = {}
    run_in_workers(math.factorial, range(8), jobs=2, threads=1, on_done=done.__setitem__,
                   worker_died=lambda task: AssertionError("no worker dies here"))
    assert done == {n: math.factorial(n) for n in range(8)}


def _root_after_the_failure(task: tuple[float, str]) -> float:
    """sqrt; a negative value fails at once, the others finish only once that failure is out."""
    value, marker = task
    if value < 0:
        Path(marker).touch()
        return math.sqrt(value)
    deadline = time.monotonic() + 30
    while not Path(marker).exists() and time.monotonic() < deadline:
        time.sleep(0.01)
    time.sleep(0.3)  # the failure's result is on its way to the parent before this one's
    return math.sqrt(value)


def test_the_first_failure_is_raised_and_no_task_starts_after_it(tmp_path):
    done = {}
    marker = str(tmp_path / "failed")
    tasks = [(value, marker) for value in (-1.0, 4.0, 9.0, 16.0, 25.0, 36.0)]
    with pytest.raises(ValueError, match="math domain error"):
        # sqrt(-1) fails on the first task; one more task was already running beside it.
        run_in_workers(_root_after_the_failure, tasks, jobs=2, threads=1, on_done=done.__setitem__,
                       worker_died=lambda task: AssertionError("no worker dies here"))
    assert {value for value, _ in done} <= {4.0}


def test_a_worker_that_dies_fails_the_run_with_the_callers_message():
    interrupted = []
    with pytest.raises(ZendarError, match="task 3 lost its worker"):
        run_in_workers(os._exit, [3], jobs=1, threads=1, on_done=lambda task, result: None,
                       worker_died=lambda task: ZendarError(f"task {task} lost its worker"),
                       on_interrupt=lambda: interrupted.append(True))
    assert interrupted == []  # a failure is not an interruption: what finished is kept


def test_usable_cpus_is_at_least_one():
    assert usable_cpus() >= 1
