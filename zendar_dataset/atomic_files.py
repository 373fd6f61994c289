"""The one way this package writes a file: a temporary sibling, fsync, then an atomic rename.

Every output file (JSON records, tables, figures, checkpoints, problem lists, static pages) goes
through :func:`write_bytes_atomic` or one of its wrappers, so a reader never sees a half-written
file and a killed run leaves only a temporary that the next run recognises and removes
(:mod:`zendar_dataset.temporary_files`). Stores that are directories (zarr scenes, dataset roots)
use the same temporary names through :mod:`zendar_dataset.format.writer`.
"""

from __future__ import annotations

import errno
import json
import os
from pathlib import Path
from typing import Any

from zendar_dataset.temporary_files import remove_stale_temporaries, remove_temporary, temporary_sibling


def write_bytes_atomic(path: str | os.PathLike, data: bytes, *, mode: int | None = None) -> None:
    """Write ``data`` to ``path`` through a temporary sibling, fsync and an atomic rename.

    The file is created with mode 0o666 minus the umask, like any file the user creates, unless
    ``mode`` is given; stale temporaries of ``path`` left by a killed run are removed first. On any
    error the temporary is removed and ``path`` is untouched.

    Parameters
    ----------
    path
        The final file; its folder must exist.
    data
        The whole content.
    mode
        Permission bits the file gets whatever the umask (e.g. 0o644 for a published page).
    """
    path = Path(path)
    remove_stale_temporaries(path.parent, path.name)
    temp = temporary_sibling(path)
    try:
        # "x": never through a file that appeared under the temporary name.
        with open(temp, "xb") as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
        if mode is not None:
            os.chmod(temp, mode)
        os.replace(temp, path)
    finally:
        remove_temporary(temp)


def write_text_atomic(path: str | os.PathLike, text: str) -> None:
    """:func:`write_bytes_atomic` of ``text`` encoded as UTF-8."""
    write_bytes_atomic(path, text.encode("utf-8"))


def json_text(value: Any, *, indent: int | None = 1, sort_keys: bool = False, allow_nan: bool = False) -> str:
    """``value`` as JSON text with a final newline (strict JSON unless ``allow_nan``)."""
    return json.dumps(value, indent=indent, sort_keys=sort_keys, allow_nan=allow_nan) + "\n"


def write_json_atomic(
    path: str | os.PathLike, value: Any, *, indent: int | None = 1, sort_keys: bool = False, allow_nan: bool = False
) -> None:
    """Write ``value`` as JSON (:func:`json_text`) to ``path`` atomically.

    Raises
    ------
    ValueError
        When ``value`` holds NaN or infinity and ``allow_nan`` is False (nothing is written).
    """
    write_text_atomic(path, json_text(value, indent=indent, sort_keys=sort_keys, allow_nan=allow_nan))


def prepare_out_dir(out_dir: str | os.PathLike) -> Path:
    """Create ``out_dir`` (and parents) unless it exists; returns it as a Path.

    Raises
    ------
    NotADirectoryError
        When ``out_dir`` (or a parent) exists and is not a directory; nothing is touched.
    """
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise NotADirectoryError(errno.ENOTDIR, "exists and is not a directory", str(out))
    out.mkdir(parents=True, exist_ok=True)
    return out
