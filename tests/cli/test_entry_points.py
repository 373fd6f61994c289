"""Every console script of pyproject.toml starts in a light module whose function installs the Ctrl-C
handler first: Ctrl-C during start-up exits 130 with ``interrupted`` and no traceback."""

from __future__ import annotations

import signal
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPTS = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]


def _run(code: str, **kwargs) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, **kwargs)


@pytest.mark.parametrize("script", sorted(SCRIPTS))
def test_the_entry_module_imports_nothing_heavy(script):
    module, function = SCRIPTS[script].split(":")
    code = f"import sys; from {module} import {function}; print(sorted({{'numpy', 'zarr', 'torch'}} & set(sys.modules)))"
    completed = _run(code)
    assert completed.returncode == 0, completed.stderr
    assert completed.stdout.strip() == "[]"


def _sigint_blocked():
    # Held pending until the entry function installs its handler (which unblocks SIGINT).
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})


@pytest.mark.parametrize("script", sorted(SCRIPTS))
def test_ctrl_c_while_a_console_script_starts_exits_130(script):
    module, function = SCRIPTS[script].split(":")
    process = subprocess.Popen(
        [sys.executable, "-c", f"import sys; from {module} import {function}; sys.exit({function}())", "--help"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=_sigint_blocked,
    )
    process.send_signal(signal.SIGINT)
    _, stderr = process.communicate(timeout=120)
    assert process.returncode == 130, (process.returncode, stderr)
    assert "Traceback" not in stderr and stderr.strip().splitlines()[-1] == "interrupted", stderr


def test_the_console_scripts_are_the_ones_the_package_knows():
    import zendar_dataset

    assert sorted(zendar_dataset.CONSOLE_SCRIPTS) == sorted(SCRIPTS)


@pytest.mark.parametrize("argv0, handler", [("/usr/bin/zendar-eval", "_exit_at_once"), ("zendar-leaderboard.exe", "_exit_at_once"),
                                            ("/usr/bin/python3", "default_int_handler")])
def test_run_as_a_console_script_the_package_import_installs_the_start_up_handler(argv0, handler):
    # Before the command's module has imported anything else: the window in which Ctrl-C printed a traceback.
    code = (f"import signal, sys; sys.argv[0] = {argv0!r}; import zendar_dataset; "
            "print(signal.getsignal(signal.SIGINT).__name__)")
    completed = _run(code)
    assert completed.returncode == 0, completed.stderr
    assert completed.stdout.strip() == handler
