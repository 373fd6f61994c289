"""The exit-status promise of every command: user error 2, environment failure 1 (naming the path
and the OS error), one line and no traceback unless ZENDAR_DEBUG=1."""

from __future__ import annotations

import json
import os
import subprocess

import pytest

from tests.format.conftest import make_dataset
from tests.reliability.outputs_helpers import BIN, assert_one_line_failure, run_in_process, run_tool
from zendar_dataset.cli.common import run_cli


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    return make_dataset(tmp_path_factory.mktemp("exit") / "ds", "hdf5")


@pytest.fixture
def eval_files(tmp_path):
    gt, pred = tmp_path / "gt.json", tmp_path / "pred.json"
    gt.write_text(json.dumps({"frames": {"s/1": [{"x": 10.0, "y": 0.0}]}}))
    pred.write_text(json.dumps({"results": {"s/1": [{"x": 10.0, "y": 0.0, "score": 1.0}]}}))
    return gt, pred


def _a_file(tmp_path):
    path = tmp_path / "mine.txt"
    path.write_text("the user's")
    return path


OUTPUT_LOCATIONS = {
    # case: (command builder, expected status, fragments of the message)
    "export-gt-o-is-a-directory": (
        lambda root, tmp, files: ("zendar-data", "export-gt", root, "--split", "train", "-o", tmp),
        1, ("Is a directory", "[EISDIR]"),
    ),
    "export-gt-o-under-a-file": (
        lambda root, tmp, files: ("zendar-data", "export-gt", root, "--split", "train", "-o", _a_file(tmp) / "gt.json"),
        1, ("Not a directory", "mine.txt"),
    ),
    "export-gt-o-exists": (
        lambda root, tmp, files: ("zendar-data", "export-gt", root, "--split", "train", "-o", _a_file(tmp)),
        2, ("exists already", "pass --overwrite"),
    ),
    "eval-out-is-a-file": (
        lambda root, tmp, files: ("zendar-eval", files[1], "--gt", files[0], "--out", _a_file(tmp)),
        1, ("cannot write", "mine.txt", "not a directory", "[ENOTDIR]"),
    ),
    "eval-out-under-a-file": (
        lambda root, tmp, files: ("zendar-eval", files[1], "--gt", files[0], "--out", _a_file(tmp) / "o"),
        1, ("cannot write", "mine.txt", "[ENOTDIR]"),
    ),
    "convert-out-under-a-file": (
        lambda root, tmp, files: ("zendar-data", "convert", root, _a_file(tmp) / "o", "--to", "zarr"),
        1, ("cannot write", "mine.txt", "[ENOTDIR]"),
    ),
    "synth-out-under-a-file": (
        lambda root, tmp, files: ("zendar-data", "synth", _a_file(tmp) / "o", "--profile", "tiny", "--quiet"),
        1, ("cannot write", "mine.txt", "[ENOTDIR]"),
    ),
}


@pytest.mark.parametrize("case", sorted(OUTPUT_LOCATIONS))
def test_bad_output_locations(tmp_path, root, eval_files, case):
    build, status, fragments = OUTPUT_LOCATIONS[case]
    result = run_in_process(*build(root, tmp_path, eval_files))
    line = assert_one_line_failure(result, status, *fragments)
    assert "[Errno" not in line
    if (tmp_path / "mine.txt").exists():
        assert (tmp_path / "mine.txt").read_text() == "the user's"


@pytest.mark.skipif(os.geteuid() == 0, reason="root is never refused permission (the read-only cases cover root)")
def test_permission_denied_exits_1(tmp_path, root):
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o500)
    result = run_in_process("zendar-data", "export-gt", root, "--split", "train", "-o", locked / "gt.json")
    assert_one_line_failure(result, 1, "Permission denied", "[EACCES]", str(locked))


def test_zendar_debug_shows_the_traceback(tmp_path, eval_files):
    gt, pred = eval_files
    command = (pred, "--gt", gt, "--out", _a_file(tmp_path))
    quiet = run_tool("zendar-eval", *command)
    assert_one_line_failure(quiet, 1, "cannot write")
    loud = run_tool("zendar-eval", *command, env={"ZENDAR_DEBUG": "1"})
    assert loud.returncode == 1
    assert "Traceback (most recent call last)" in loud.stderr and "NotADirectoryError" in loud.stderr
    assert loud.stderr.rstrip().splitlines()[-1] == quiet.stderr.rstrip()


def test_an_unexpected_exception_is_one_line_and_exit_1(capsys):
    def body():
        raise TypeError("unsupported operand type(s) for +: 'int' and 'str'\nsecond line")

    assert run_cli(body) == 1
    err = capsys.readouterr().err
    assert err == (
        "error: unexpected TypeError: unsupported operand type(s) for +: 'int' and 'str' "
        "(a bug; set ZENDAR_DEBUG=1 for the traceback)\n"
    )


@pytest.mark.slow
def test_a_closed_output_pipe_is_no_traceback(root):
    # The reader of stdout goes away at once (like `| head` that has read enough).
    process = subprocess.Popen(
        [str(BIN / "zendar-data"), "info", str(root)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    process.stdout.close()
    stderr = process.stderr.read()
    assert process.wait(timeout=120) == 1
    assert stderr == ""
