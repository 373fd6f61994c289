"""Temporaries: a rerun removes exactly what a killed run of this package left, nothing of the user's;
outputs are created with the user's umask."""

from __future__ import annotations

import json
import os
import signal
import stat
import subprocess
import sys
import textwrap

import pytest

from tests.format.conftest import make_dataset
from tests.reliability.outputs_helpers import hidden_entries, run_in_process
from zendar_dataset import temporary_files


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    return make_dataset(tmp_path_factory.mktemp("temps") / "ds", "zarr")


def _dead_pid() -> int:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def _stale_temporary(final, pid: int, directory: bool = True):
    """A temporary of ``final`` named as the package names them, as if process ``pid`` had made it."""
    nonce = "0badc0de"
    temp = final.parent / f".{final.name}.tmp-{pid}-{nonce}{temporary_files._check(final.name, pid, nonce)}"
    if directory:
        (temp / "scenes").mkdir(parents=True)
        (temp / "scenes" / "chunk").write_bytes(b"x" * 1000)
    else:
        temp.write_bytes(b"partial")
    return temp


def test_convert_killed_with_sigkill_leaves_a_temporary_that_the_rerun_removes_and_nothing_else(tmp_path, root):
    out = tmp_path / "out"
    # Convert in a child that stops after its first scene, then kill it as the OOM killer would.
    script = textwrap.dedent(
        f"""
        import sys, time
        from zendar_dataset.format import convert
        copy = convert.convert_scene
        def slow(*args, **kwargs):
            copy(*args, **kwargs)
            print("scene done", flush=True)
            time.sleep(600)
        convert.convert_scene = slow
        convert.convert_dataset({str(root)!r}, {str(out)!r}, to="hdf5")
        """
    )
    child = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout.readline().strip() == "scene done"
    finally:
        child.send_signal(signal.SIGKILL)
        child.wait()
    left = hidden_entries(tmp_path)
    assert left and left[0].startswith(f".out.tmp-{child.pid}-"), left
    # Look-alikes that are not stale temporaries of this package: the user's name, the pattern with a
    # wrong check, and a temporary of a process that is still running.
    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(120)"])
    try:
        kept = [tmp_path / ".out.tmp-mine", tmp_path / ".out.tmp-1-0badc0de00000000"]
        for path in kept:
            (path / "scenes").mkdir(parents=True)
        kept.append(_stale_temporary(out, sleeper.pid))
        result = run_in_process("zendar-data", "convert", root, out, "--to", "hdf5")
    finally:
        sleeper.kill()
        sleeper.wait()
    assert result.returncode == 0, result.stderr
    assert hidden_entries(tmp_path) == sorted(path.name for path in kept)  # the killed run's is gone
    assert all((path / "scenes").is_dir() for path in kept)
    assert json.loads((out / "dataset.json").read_text())["scenes"]


def test_stale_temporaries_of_scenes_and_json_are_removed_by_the_next_write(tmp_path):
    from zendar_dataset.atomic_files import write_json_atomic

    pid = _dead_pid()
    stale = _stale_temporary(tmp_path / "gt.json", pid, directory=False)
    other = _stale_temporary(tmp_path / "other.json", pid, directory=False)  # not this output's: left alone
    write_json_atomic(tmp_path / "gt.json", {"frames": {}})
    assert not stale.exists() and other.exists()


@pytest.mark.slow
def test_synth_resume_keeps_the_users_look_alike_directory(tmp_path):
    from zendar_dataset.sim.generate import synthesize_dataset

    out = tmp_path / "sim"
    synthesize_dataset(out, profile="tiny", n_scenes=1, seed=5, progress=False, jobs=1)
    mine = out / "scenes" / ".scene-0000.zarr.tmp-mine"
    (mine / "notes").mkdir(parents=True)
    stale = _stale_temporary(out / "scenes" / "scene-0000.zarr", _dead_pid())
    synthesize_dataset(out, profile="tiny", n_scenes=1, seed=5, progress=False, jobs=1)  # resume: nothing left to do
    assert (mine / "notes").is_dir()
    assert not stale.exists()


@pytest.mark.parametrize("umask", [0o022, 0o027])
@pytest.mark.parametrize("output", ["metrics.json", "pr_far.png", "problems.txt"])
def test_evaluator_outputs_are_created_with_the_users_umask(tmp_path, umask, output):
    (tmp_path / "gt.json").write_text(json.dumps({"frames": {"s/1": [{"x": 40.0, "y": 0.0}]}}))
    score = "high" if output == "problems.txt" else 1.0
    (tmp_path / "p.json").write_text(json.dumps({"results": {"s/1": [{"x": 40.0, "y": 0.0, "score": score}]}}))
    previous = os.umask(umask)
    try:
        run_in_process(
            "zendar-eval", tmp_path / "p.json", "--gt", tmp_path / "gt.json", "--out", tmp_path / "o", "--plot"
        )
    finally:
        os.umask(previous)
    assert stat.S_IMODE((tmp_path / "o" / output).stat().st_mode) == 0o666 & ~umask
