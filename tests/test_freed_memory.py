"""Freed memory is kept for reuse: a step that frees 80 MiB at once and takes it again faults no page
back in, in worker processes and under every command, while glibc's defaults fault it in every step."""

from __future__ import annotations

import platform
import resource
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from zendar_dataset.worker_pool import run_in_workers

pytestmark = pytest.mark.skipif(
    platform.system() != "Linux" or platform.libc_ver()[0] != "glibc", reason="the settings are glibc's"
)


def faults_per_step(_task: object = None) -> float:
    """Minor page faults per step of a training-like pattern: ten 8 MiB arrays written, then freed together."""

    def step() -> None:
        held = [np.ones(1 << 20) for _ in range(10)]
        del held

    step()
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(10):
        step()
    return (resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before) / 10


def _in_fresh_process(code: str) -> float:
    """The last line ``code`` prints, run in a new interpreter (this one's allocator is already set)."""
    prelude = "from tests.test_freed_memory import faults_per_step\n"
    done = subprocess.run([sys.executable, "-c", prelude + textwrap.dedent(code)], capture_output=True, text=True,
                          check=True, cwd=_repo_root())
    return float(done.stdout.strip().splitlines()[-1])


def _repo_root() -> str:
    from pathlib import Path

    return str(Path(__file__).resolve().parents[1])


def test_the_defaults_fault_freed_memory_in_again_and_the_setting_does_not():
    default = _in_fresh_process("print(faults_per_step())")
    kept = _in_fresh_process("""
        from zendar_dataset.freed_memory import keep_freed_memory
        assert keep_freed_memory()
        print(faults_per_step())
    """)
    # 80 MiB is 20480 pages; the defaults give back (and fault in) a fifth to a quarter of it per step
    # (4649 to 5121 pages measured, depending on what the interpreter allocated before).
    assert default > 2000
    assert kept < 50


def test_every_command_keeps_freed_memory():
    kept = _in_fresh_process("""
        from zendar_dataset.cli.common import run_cli
        run_cli(lambda: print(faults_per_step()))
    """)
    assert kept < 50


def test_worker_processes_keep_freed_memory():
    done = {}
    run_in_workers(faults_per_step, [0], jobs=1, threads=1, on_done=done.__setitem__,
                   worker_died=lambda task: AssertionError("no worker dies here"))
    assert done[0] < 50
