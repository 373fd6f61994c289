"""Every command that writes, on a full disk and on a read-only file system: exit status 1 and one
line naming the path and the OS error; never a traceback, never a crash by signal (HDF5 used to end
in a segmentation fault, exit 139); no temporary left behind.

Mounts a small tmpfs (needs root); skips with the reason where the machine does not allow it.
"""

from __future__ import annotations

import json

import pytest

from tests.format.conftest import make_dataset
from tests.reliability.outputs_helpers import (
    assert_one_line_failure,
    hidden_entries,
    run_in_process,
    run_tool,
    small_file_system,
)


@pytest.fixture(scope="module")
def source(tmp_path_factory):
    """A labelled dataset whose conversion needs about 1 MB (80 radar cubes of 4 KiB per scene)."""
    return make_dataset(tmp_path_factory.mktemp("source") / "ds", "zarr", n_frames=40)


@pytest.fixture(scope="module")
def eval_inputs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("eval")
    (folder / "gt.json").write_text(json.dumps({"frames": {"s/1": [{"x": 10.0, "y": 0.0}]}}))
    predictions = {"meta": {"method": "m"}, "results": {"s/1": [{"x": 10.5, "y": 0.0, "score": 0.9}]}}
    (folder / "pred.json").write_text(json.dumps(predictions))
    return folder


def _convert(source, target, backend):
    return ("zendar-data", "convert", source, target / "out", "--to", backend)


def _export_gt(source, target, _):
    return ("zendar-data", "export-gt", source, "--split", "train", "-o", target / "gt.json")


def _synth(_, target, backend):
    return ("zendar-data", "synth", target / "out", "--profile", "tiny", "--scenes", "1", "--jobs", "1",
            "--quiet", "--backend", backend)


WRITERS = {
    "convert-hdf5": (_convert, "hdf5"),
    "convert-zarr": (_convert, "zarr"),
    "export-gt": (_export_gt, None),
    "synth-hdf5": (_synth, "hdf5"),
    "synth-zarr": (_synth, "zarr"),
}


@pytest.mark.slow
@pytest.mark.parametrize("case", ["convert-hdf5", "convert-zarr"])
def test_convert_running_out_of_space_midway_exits_1_and_leaves_nothing(tmp_path, source, case):
    command, backend = WRITERS[case]
    with small_file_system(tmp_path / "disk", "256k") as disk:
        result = run_tool(*command(source, disk, backend))
        assert_one_line_failure(result, 1, "No space left on device", str(disk / "out"))
        assert not (disk / "out").exists()
        assert hidden_entries(disk) == []


@pytest.mark.slow
@pytest.mark.parametrize("backend", ["hdf5", "zarr"])
def test_synth_running_out_of_space_midway_exits_1(tmp_path, backend):
    with small_file_system(tmp_path / "disk", "1m") as disk:
        result = run_tool(*_synth(None, disk, backend))
        # The scene and its store's path (the raw write of a zarr chunk names no file of its own).
        assert_one_line_failure(result, 1, "No space left on device", "scene-0000", str(disk / "out" / "scenes"))
        assert not (disk / "out" / "dataset.json").exists()
        assert hidden_entries(disk / "out" / "scenes") == []


@pytest.mark.parametrize("case", sorted(WRITERS) + ["zendar-eval"])
@pytest.mark.parametrize("failure", ["full", "read-only"])
def test_every_writer_on_a_full_or_read_only_disk_exits_1(tmp_path, source, eval_inputs, capsys, case, failure):
    # In this process (the subprocess cases above cover the crash): the same run_cli as the console scripts.
    with small_file_system(tmp_path / "disk", "256k", full=failure == "full", read_only=failure == "read-only") as disk:
        if case == "zendar-eval":
            command = ("zendar-eval", eval_inputs / "pred.json", "--gt", eval_inputs / "gt.json", "--out", disk / "o")
        else:
            build, backend = WRITERS[case]
            command = build(source, disk, backend)
        result = run_in_process(*command)
        reason = "No space left on device" if failure == "full" else "Read-only file system"
        assert_one_line_failure(result, 1, reason, str(disk))
        assert hidden_entries(disk) == []
