"""Running the command-line tools as a user does, and places to write that fail on purpose."""

from __future__ import annotations

import contextlib
import os
import pathlib
import subprocess
import sys

import pytest

BIN = pathlib.Path(sys.executable).parent


def run_tool(tool: str, *args, env: dict | None = None, timeout: float = 300) -> subprocess.CompletedProcess:
    """Run the console script ``tool`` (``zendar-data``, ``zendar-eval``) with ``args``; text output captured."""
    script = BIN / tool
    command = [str(script)] if script.exists() else [sys.executable, "-m", f"zendar_dataset.cli.{tool.split('-')[1]}"]
    full_env = {key: value for key, value in os.environ.items() if key != "ZENDAR_DEBUG"}
    full_env.update(env or {})
    return subprocess.run(
        command + [str(a) for a in args], capture_output=True, text=True, timeout=timeout, env=full_env
    )


def run_in_process(tool: str, *args) -> subprocess.CompletedProcess:
    """Run ``tool``'s ``main`` in this process; its status and stdout/stderr as a CompletedProcess."""
    import io

    from zendar_dataset.cli import data, eval as eval_cli

    main = {"zendar-data": data.main, "zendar-eval": eval_cli.main}[tool]
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            status = main([str(a) for a in args])
        except SystemExit as exc:  # argparse
            status = exc.code
    return subprocess.CompletedProcess([tool, *map(str, args)], status, out.getvalue(), err.getvalue())


def assert_one_line_failure(result: subprocess.CompletedProcess, status: int, *fragments: str) -> str:
    """The run exited with ``status``, printed no traceback and exactly one ``error:`` line holding ``fragments``."""
    stderr = result.stderr
    assert result.returncode == status, (result.returncode, stderr[-3000:])
    assert "Traceback" not in stderr and "Exception ignored" not in stderr, stderr[-3000:]
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), stderr[-3000:]
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    return lines[0]


def _mount_tmpfs(directory: pathlib.Path, options: str) -> None:
    directory.mkdir(parents=True, exist_ok=True)
    if os.geteuid() != 0:
        pytest.skip("a small file system for the disk-full and read-only cases needs root (mount -t tmpfs)")
    result = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(directory)], capture_output=True, text=True
    )
    if result.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here for the disk-full cases: {result.stderr.strip()}")


@contextlib.contextmanager
def small_file_system(directory: pathlib.Path, size: str = "256k", *, full: bool = False, read_only: bool = False):
    """A tmpfs of ``size`` at ``directory``; ``full`` fills it up first, ``read_only`` remounts it read-only.

    Skips the test (with the reason) where mounting is not allowed.
    """
    _mount_tmpfs(directory, f"size={size},mode=0777")
    try:
        if full:
            with contextlib.suppress(OSError), open(directory / "filler", "wb") as handle:
                block = b"\0" * 65536
                while True:
                    handle.write(block)
                    handle.flush()
        if read_only:
            subprocess.run(["mount", "-o", "remount,ro", str(directory)], check=True, capture_output=True)
        yield directory
    finally:
        subprocess.run(["umount", "-l", str(directory)], capture_output=True)


def hidden_entries(directory: pathlib.Path) -> list[str]:
    """Names starting with a dot under ``directory`` (where temporaries live), recursively."""
    if not directory.exists():
        return []
    return sorted(str(p.relative_to(directory)) for p in directory.rglob(".*"))
