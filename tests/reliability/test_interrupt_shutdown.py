"""Ctrl-C after a command has returned: its exit status stands (no death by signal at shutdown)."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

_SCRIPT = textwrap.dedent(
    """
    import os, signal, sys
    from zendar_dataset.cli.interrupt import console_script

    @console_script
    def tool():
        return {status}

    status = tool()
    # The command is done; a Ctrl-C now lands while the interpreter shuts down.
    os.kill(os.getpid(), signal.SIGINT)
    sys.exit(status)
    """
)


@pytest.mark.parametrize("status", [0, 2])
def test_a_ctrl_c_after_the_command_returned_leaves_its_status(status):
    done = subprocess.run(
        [sys.executable, "-c", _SCRIPT.format(status=status)], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == status, (done.returncode, done.stderr)
    assert done.stderr == ""


def test_the_console_scripts_are_wrapped():
    from zendar_baselines.entry import zendar_bench
    from zendar_dataset.cli.data import zendar_data
    from zendar_dataset.cli.eval import zendar_eval
    from zendar_leaderboard.cli import zendar_leaderboard

    for script in (zendar_bench, zendar_data, zendar_eval, zendar_leaderboard):
        assert script.__wrapped__.__name__ == script.__name__
