"""Temporary siblings of outputs, recognisable as this package's own, and their clean-up.

Every output is written under a hidden temporary sibling and renamed into
place.  The sibling's name marks it as ours::

    .<final name>.tmp-<pid>-<nonce><check>

``pid`` is the writing process, ``nonce`` 8 random hex digits and ``check``
the first 8 hex digits of a BLAKE2 hash of the final name, the pid and the
nonce.  The name carries its own proof, so it works for files (HDF5 stores,
JSON, PNG) and directories (zarr stores, dataset roots) alike and nothing
extra lands inside a store that is later renamed into place.  A user's entry
that merely looks similar (``.scene-0000.zarr.tmp-mine``) fails the check and
is never touched.

A temporary is *stale* when it is ours and its process is gone (or it carries
this process's pid but this process did not create it: a reused pid); a
re-run removes exactly the stale temporaries of the outputs it writes.
"""

from __future__ import annotations

import hashlib
import os
import pathlib
import re
import secrets
import shutil
import time

_NAME = re.compile(r"^\.(?P<name>.+)\.tmp-(?P<pid>[0-9]+)-(?P<nonce>[0-9a-f]{8})(?P<check>[0-9a-f]{8})$")
# Temporaries this process created and has not yet renamed or removed (a dead twin's pid may equal ours).
_LIVE: set[str] = set()
_SETTLE_S = 2.0


def _check(name: str, pid: int, nonce: str) -> str:
    return hashlib.blake2b(f"zendar-dataset\0{name}\0{pid}\0{nonce}".encode(), digest_size=4).hexdigest()


def temporary_sibling(path: str | os.PathLike) -> pathlib.Path:
    """A fresh temporary name beside ``path`` (nothing is created).

    Parameters
    ----------
    path
        The final output path.

    Returns
    -------
    pathlib.Path
        ``path.parent / ".<name>.tmp-<pid>-<nonce><check>"``, registered as live in this process
        until :func:`forget` or :func:`remove_temporary` is called on it.
    """
    path = pathlib.Path(path)
    pid = os.getpid()
    nonce = secrets.token_hex(4)
    temp = path.parent / f".{path.name}.tmp-{pid}-{nonce}{_check(path.name, pid, nonce)}"
    _LIVE.add(str(temp))
    return temp


def forget(temp: str | os.PathLike) -> None:
    """Mark ``temp`` as no longer this process's (renamed into place or removed)."""
    _LIVE.discard(str(temp))


def owner_pid(path: str | os.PathLike) -> int | None:
    """The pid of the process that created ``path`` when it is one of our temporaries, else None."""
    match = _NAME.match(pathlib.Path(path).name)
    if match is None:
        return None
    pid = int(match["pid"])
    return pid if _check(match["name"], pid, match["nonce"]) == match["check"] else None


def _process_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, owned by another user
        return True
    except OverflowError:
        return False
    return True


def is_stale(path: str | os.PathLike) -> bool:
    """True when ``path`` is one of our temporaries and the process that created it is gone."""
    pid = owner_pid(path)
    if pid is None:
        return False
    if pid == os.getpid():
        return str(path) not in _LIVE
    return not _process_alive(pid)


def remove_temporary(temp: str | os.PathLike) -> None:
    """Remove a temporary file or directory tree (if present) and forget it."""
    temp = pathlib.Path(temp)
    if temp.is_dir() and not temp.is_symlink():
        # After one chunk write of a zarr call fails, its sibling writes still run for a moment on
        # zarr's event loop (asyncio.gather does not cancel them) and recreate directories: remove
        # until the path has stayed absent for a few polls.
        deadline = time.monotonic() + _SETTLE_S
        absent_polls = 0
        while absent_polls < 3 and time.monotonic() < deadline:
            if os.path.lexists(temp):
                shutil.rmtree(temp, ignore_errors=True)
                absent_polls = 0
            else:
                absent_polls += 1
            time.sleep(0.02)
    else:
        temp.unlink(missing_ok=True)
    forget(temp)


def remove_stale_temporaries(directory: str | os.PathLike, final_name: str | None = None) -> list[pathlib.Path]:
    """Remove the stale temporaries in ``directory`` (of ``final_name`` only, when given).

    Parameters
    ----------
    directory
        Where the outputs are written; a missing directory has nothing to remove.
    final_name
        Restrict to temporaries of this output name (e.g. ``"scene-0003.zarr"``).

    Returns
    -------
    list of pathlib.Path
        What was removed.
    """
    directory = pathlib.Path(directory)
    prefix = "." if final_name is None else f".{final_name}.tmp-"
    try:
        entries = [entry for entry in os.scandir(directory) if entry.name.startswith(prefix)]
    except (FileNotFoundError, NotADirectoryError):
        return []
    removed = []
    for entry in entries:
        match = _NAME.match(entry.name)
        if match is None or (final_name is not None and match["name"] != final_name):
            continue
        path = directory / entry.name
        if is_stale(path):
            remove_temporary(path)
            removed.append(path)
    return removed


__all__ = ["forget", "is_stale", "owner_pid", "remove_stale_temporaries", "remove_temporary", "temporary_sibling"]
