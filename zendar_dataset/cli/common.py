"""Shared behaviour of the command-line tools: the exit-status promise, never a traceback.

- A problem with the user's files or arguments (:class:`ZendarError`, an input
  path that does not exist): a one-line message, exit status 2.  A list of
  problems shows the first :data:`MAX_PROBLEMS_SHOWN` and the count.
- A failure of the environment (disk full, read-only file system, permission
  denied, an output location that is a file or a missing directory): a
  one-line message naming the path and the OS error, exit status 1.
- Ctrl-C: exit status 130.
- Anything else is a bug: a one-line message, exit status 1.

Set ``ZENDAR_DEBUG=1`` to also see the traceback.

Every command keeps the memory it frees for reuse (:mod:`zendar_dataset.freed_memory`): training
and simulation free tens of MB per step, which the C library would otherwise hand back to the
kernel and fault in again.
"""

from __future__ import annotations

import errno
import os
import sys
import traceback
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from zendar_dataset.cli.interrupt import EXIT_INTERRUPTED, interrupts_raise
from zendar_dataset.errors import ZendarError
from zendar_dataset.freed_memory import keep_freed_memory

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_USAGE = 2

#: At most this many problems are printed; the rest are counted (and written to a file where a command can).
MAX_PROBLEMS_SHOWN = 50

# OS errors that say the environment refused a write, whichever file they name (not EIO: a bad
# sector in an input is not a failure to write the output).
_WRITE_FAILURES = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EFBIG})


class OutputError(Exception):
    """Writing an output failed in the environment; exit status 1.

    Attributes
    ----------
    path
        The output the user named (``OUT``, ``-o``, ``--out``).
    error
        The OS error, which may name a file inside ``path``.
    """

    def __init__(self, path: str | os.PathLike, error: OSError) -> None:
        named = error.filename is not None and os.path.abspath(os.fspath(error.filename)) == os.path.abspath(path)
        super().__init__(f"cannot write {os.fspath(path)}: {describe_os_error(error, with_file=not named)}")
        self.path = os.fspath(path)
        self.error = error


def describe_os_error(error: OSError, with_file: bool = True) -> str:
    """``"No space left on device [ENOSPC]: '/mnt/x/.out.tmp-…'"``: the OS's words, its code and the file."""
    code = errno.errorcode.get(error.errno, "") if error.errno is not None else ""
    text = error.strerror or str(error)
    text += f" [{code}]" if code else ""
    if with_file and error.filename is not None:
        text += f": {os.fspath(error.filename)!r}"
    return text


def _is_about(error: OSError, output: str) -> bool:
    """Whether ``error`` names ``output``, something inside it or one of its temporary siblings."""
    if error.filename is None:
        return False
    name = os.path.abspath(os.fspath(error.filename))
    target = os.path.abspath(output)
    parent, base = os.path.split(target)
    if name == target or name.startswith(target + os.sep):
        return True
    # A parent that is a file or missing shows up as an error naming that parent.
    if target.startswith(name + os.sep):
        return True
    sibling = os.path.join(parent, "." + base + ".")
    return name.startswith(sibling)


@contextmanager
def writing(output: str | os.PathLike) -> Iterator[None]:
    """Turn an OS error on the way to ``output`` into an :class:`OutputError` (exit status 1).

    Errors about other paths (an input that does not exist) pass through unchanged.
    """
    try:
        yield
    except OSError as exc:
        named = os.path.abspath(os.fspath(exc.filename)) if exc.filename is not None else None
        target = os.path.abspath(os.fspath(output))
        if isinstance(exc, FileExistsError) and named is not None:
            if named == target:
                raise  # the output exists: the command says what to do about it
            if target.startswith(named + os.sep) and not os.path.isdir(named):
                # mkdir(parents=True) says "File exists" for a parent that is a file.
                exc = NotADirectoryError(errno.ENOTDIR, os.strerror(errno.ENOTDIR), exc.filename)
        if exc.errno in _WRITE_FAILURES or _is_about(exc, os.fspath(output)):
            raise OutputError(output, exc) from exc
        raise


def print_problems(problems: list[str], problems_file: str | None = None) -> None:
    """Print ``problems`` to stderr: the first :data:`MAX_PROBLEMS_SHOWN` and how many there are."""
    if len(problems) == 1:
        print(f"error: {problems[0]}" + (f" (also in {problems_file})" if problems_file else ""), file=sys.stderr)
        return
    where = f"; all of them are in {problems_file}" if problems_file else ""
    print(f"error: {len(problems)} problems found{where}:", file=sys.stderr)
    for problem in problems[:MAX_PROBLEMS_SHOWN]:
        print(f"  - {problem}", file=sys.stderr)
    hidden = len(problems) - MAX_PROBLEMS_SHOWN
    if hidden > 0:
        tail = f" (full list in {problems_file})" if problems_file else ""
        print(f"  ... and {hidden} more, {len(problems)} problems in all{tail}", file=sys.stderr)


def _debug() -> bool:
    return os.environ.get("ZENDAR_DEBUG", "") not in ("", "0")


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def run_cli(body: Callable[[], int | None]) -> int:
    """Run ``body`` under the exit-status promise of the module docstring.

    Parameters
    ----------
    body
        The command's work; returns an exit status or None for success.

    Returns
    -------
    int
        The process exit status: 0, 1 (environment failure or bug), 2 (user error) or 130 (Ctrl-C).
    """
    keep_freed_memory()
    try:
        with interrupts_raise():
            status = body()
        sys.stdout.flush()  # a closed pipe surfaces here, not at interpreter exit
    except KeyboardInterrupt:
        # Ctrl-C inside zarr's asynchronous writes leaves coroutines never awaited; their warnings at
        # garbage collection would follow the one line a user should see last.
        warnings.filterwarnings("ignore", message="coroutine .* was never awaited", category=RuntimeWarning)
        print("interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BaseException as exc:  # noqa: BLE001 - every exception ends as a message and a status
        if isinstance(exc, SystemExit):
            raise
        if _debug():
            traceback.print_exc()
        return _report(exc)
    return EXIT_OK if status is None else int(status)


def _report(exc: BaseException) -> int:
    """Print the one-line message for ``exc`` and return its exit status."""
    if isinstance(exc, ZendarError):
        problems = getattr(exc, "problems", None) or [str(exc)]
        print_problems(problems, getattr(exc, "problems_file", None))
        return EXIT_USAGE
    if isinstance(exc, OutputError):
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    if isinstance(exc, BrokenPipeError):
        # The reader of our output went away (``| head``): nothing left to say to it.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_FAILURE
    if isinstance(exc, (FileNotFoundError, NotADirectoryError)):
        what = "no such file or directory" if isinstance(exc, FileNotFoundError) else "not a directory"
        print(f"error: {what}: {exc.filename if exc.filename is not None else exc}", file=sys.stderr)
        return EXIT_USAGE
    if isinstance(exc, OSError):
        print(f"error: {describe_os_error(exc)}", file=sys.stderr)
        return EXIT_FAILURE
    if isinstance(exc, MemoryError):
        print("error: out of memory", file=sys.stderr)
        return EXIT_FAILURE
    synthesis_error = getattr(sys.modules.get("zendar_dataset.sim.generate"), "SceneSynthesisError", None)
    if synthesis_error is not None and isinstance(exc, synthesis_error):
        print(f"error: {_first_line(exc)}", file=sys.stderr)
        return EXIT_FAILURE
    print(
        f"error: unexpected {type(exc).__name__}: {_first_line(exc)} (a bug; set ZENDAR_DEBUG=1 for the traceback)",
        file=sys.stderr,
    )
    return EXIT_FAILURE
