"""Shared behaviour of the command-line tools: user errors exit 2, no traceback."""

from __future__ import annotations

import sys
from collections.abc import Callable

from zendar_dataset.cli.interrupt import EXIT_INTERRUPTED, interrupts_raise
from zendar_dataset.errors import ZendarError

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_USAGE = 2


def run_cli(body: Callable[[], int | None]) -> int:
    """Run ``body`` and turn user errors into a message on stderr and exit status 2.

    Parameters
    ----------
    body
        The command's work; returns an exit status or None for success.

    Returns
    -------
    int
        The process exit status.
    """
    try:
        with interrupts_raise():
            status = body()
    except ZendarError as exc:
        problems = getattr(exc, "problems", None) or [str(exc)]
        if len(problems) > 1:
            print(f"error: {len(problems)} problems found:", file=sys.stderr)
            for problem in problems:
                print(f"  - {problem}", file=sys.stderr)
        else:
            print(f"error: {problems[0]}", file=sys.stderr)
        return EXIT_USAGE
    except FileNotFoundError as exc:
        print(f"error: no such file or directory: {exc.filename or exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    return EXIT_OK if status is None else int(status)
