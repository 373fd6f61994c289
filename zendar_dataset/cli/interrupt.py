"""Ctrl-C for the command-line tools: exit status 130 and no traceback, whenever it lands.

Two phases. While a tool starts (imports, argument parsing) nothing has been
written, so SIGINT ends the process at once. While a command works, SIGINT
raises ``KeyboardInterrupt`` so that cleanups run (workers stopped, temporary
stores removed), and :func:`interrupts_raise` turns whatever the interrupt
became on its way out into ``KeyboardInterrupt`` (inside a numba kernel it
surfaces as a ``SystemError``). Both phases install their handler explicitly
and unblock SIGINT, so a disposition inherited from the parent (ignored under
``nohup`` or ``cmd &`` in a script, or blocked) does not swallow Ctrl-C.

Each console script's function (``zendar_dataset.cli.data.zendar_data``,
``zendar_dataset.cli.eval.zendar_eval``, ``zendar_baselines.entry.zendar_bench``,
``zendar_leaderboard.cli.zendar_leaderboard``) is wrapped in :func:`console_script`,
in a module that imports nothing heavy, so the start-up handler is in place
before the heavy imports. A third phase begins when the command returns: its
exit status is decided, and Ctrl-C is ignored while the interpreter shuts down
(Python puts SIGINT back to its default as it finalises, so a late Ctrl-C would
otherwise kill the process by signal instead of letting the status stand).
"""

from __future__ import annotations

import _thread
import logging
import os
import signal
import sys
import threading
import functools
from collections.abc import Callable, Iterator
from typing import Any
from contextlib import contextmanager

EXIT_INTERRUPTED = 130

_interrupted = False


def _exit_at_once(signum: int, frame: object) -> None:
    # Starting up: nothing written yet, nothing to clean.
    os.write(2, b"interrupted\n")
    os._exit(EXIT_INTERRUPTED)


def _raise_interrupt(signum: int, frame: object) -> None:
    global _interrupted
    if _interrupted:
        return  # a second Ctrl-C must not cut the cleanup of the first short
    _interrupted = True
    raise KeyboardInterrupt


def _interrupt_in_callback(previous_hook: Callable[[Any], None], unraisable: Any) -> None:
    """``sys.unraisablehook`` within :func:`interrupts_raise`.

    A Ctrl-C that lands in a Python callback run by C code (llvmlite's object-cache notice while numba
    compiles) cannot propagate from there: Python would print it, traceback and all, and carry on. It is
    raised again 10 ms later, from another thread (raised from here it would land in the callback again),
    which the callback has left by then (else this repeats); anything else goes to ``previous_hook``.
    """
    global _interrupted
    if unraisable.exc_type is not None and issubclass(unraisable.exc_type, KeyboardInterrupt):
        _interrupted = False
        threading.Timer(0.01, _thread.interrupt_main).start()
        return
    previous_hook(unraisable)


def _install(handler) -> object:
    previous = signal.signal(signal.SIGINT, handler)
    if hasattr(signal, "pthread_sigmask"):  # POSIX only
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    return previous


def exit_while_starting() -> None:
    """Make Ctrl-C exit with status 130 at once (for the start-up of a command-line tool)."""
    if threading.current_thread() is threading.main_thread():
        _install(_exit_at_once)


def console_script(main: Callable[[], int]) -> Callable[[], int]:
    """Wrap a console script's function in the three Ctrl-C phases of the module docstring."""

    @functools.wraps(main)
    def run() -> int:
        exit_while_starting()
        status = main()
        if threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGINT, signal.SIG_IGN)
        return status

    return run


@contextmanager
def interrupts_raise() -> Iterator[None]:
    """Within the block Ctrl-C raises ``KeyboardInterrupt``, whatever it became on the way out.

    Raises
    ------
    KeyboardInterrupt
        When SIGINT arrived in the block: in place of the exception the
        interrupt turned into, or at the end of the block if it was swallowed.

    The previous SIGINT handler is restored afterwards (a no-op outside the
    main thread, where handlers cannot be installed).
    """
    global _interrupted
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _interrupted = False
    previous = _install(_raise_interrupt)
    previous_hook = sys.unraisablehook
    sys.unraisablehook = functools.partial(_interrupt_in_callback, previous_hook)
    try:
        yield
    except KeyboardInterrupt:
        _quiet_abandoned_io()
        raise
    except BaseException as exc:
        if _interrupted:
            _quiet_abandoned_io()
            raise KeyboardInterrupt from exc
        raise
    else:
        if _interrupted:
            _quiet_abandoned_io()
            raise KeyboardInterrupt
    finally:
        sys.unraisablehook = previous_hook
        signal.signal(signal.SIGINT, previous)


def _quiet_abandoned_io() -> None:
    # zarr does its I/O on an asyncio loop in a background thread; an interrupted write leaves
    # its coroutine pending, and asyncio would log "Task was destroyed but it is pending!" at exit.
    logging.getLogger("asyncio").setLevel(logging.CRITICAL + 1)


__all__ = ["EXIT_INTERRUPTED", "console_script", "exit_while_starting", "interrupts_raise"]
