"""Static export: ``index.html``, ``leaderboard.json``, ``leaderboard.csv`` and ``entry/ID.html``.

The files need no server: styles and the sorting script are inside the pages, links are relative,
so the folder works opened from disk or from any static host.

Each render builds the whole site afresh in a temporary sibling of OUT and swaps it in with one
atomic rename, so a hidden or deleted entry's page, scores and meta leave the published folder
with the next render, and a reader never sees half of one export and half of another. OUT must be
new, empty, or a previous export: one holding its manifest (:data:`MANIFEST_NAME`, the list of
files that export wrote) and nothing else. Any other folder is refused, so a render never deletes
a file it did not write.
"""

from __future__ import annotations

import ctypes
import errno
import os
from pathlib import Path

import orjson

from zendar_dataset.atomic_files import write_bytes_atomic
from zendar_dataset.errors import ZendarError
from zendar_dataset.temporary_files import forget, remove_stale_temporaries, remove_temporary, temporary_sibling
from zendar_leaderboard import ranking
from zendar_leaderboard.pages import entry_page, ranking_page
from zendar_leaderboard.store import Store

# A published site is read by a web server running as another user, whatever the publisher's umask.
PUBLISHED_MODE = 0o644
PUBLISHED_FOLDER_MODE = 0o755

#: The file that marks a folder as this export's and lists what it wrote (relative POSIX paths).
MANIFEST_NAME = ".zendar-leaderboard-export.json"

# renameat2(2): AT_FDCWD and RENAME_EXCHANGE from <fcntl.h> and <linux/fs.h>.
_AT_FDCWD = -100
_RENAME_EXCHANGE = 2


def _exchange(first: Path, second: Path) -> bool:
    """Swap two existing paths in one atomic step (Linux ``renameat2``); False where unsupported."""
    renameat2 = getattr(ctypes.CDLL(None, use_errno=True), "renameat2", None)
    if renameat2 is None:
        return False
    renameat2.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    if renameat2(_AT_FDCWD, os.fsencode(first), _AT_FDCWD, os.fsencode(second), _RENAME_EXCHANGE) == 0:
        return True
    code = ctypes.get_errno()
    if code in (errno.EINVAL, errno.ENOSYS, errno.ENOTSUP):  # a file system or kernel without it
        return False
    raise OSError(code, os.strerror(code), str(second))


def _previous_export(out: Path, shown: str) -> None:
    """Refuse ``out`` unless it is empty or holds only what a previous export wrote."""
    present = sorted(path.relative_to(out).as_posix() for path in out.rglob("*") if not path.is_dir())
    if not present:
        return
    manifest = out / MANIFEST_NAME
    if not manifest.is_file():
        raise ZendarError(
            f"output {shown!r} is a folder that is not a leaderboard export (no {MANIFEST_NAME} in it): "
            "render into a new or empty folder"
        )
    try:
        written = set(orjson.loads(manifest.read_bytes())["files"])
    except (OSError, orjson.JSONDecodeError, KeyError, TypeError):
        raise ZendarError(
            f"output {shown!r} holds a {MANIFEST_NAME} that cannot be read as an export's list of files, so "
            "it is not known which files a render may replace: render into a new or empty folder"
        ) from None
    foreign = [name for name in present if name not in written and name != MANIFEST_NAME]
    foreign += sorted(  # folders the export did not make, even empty ones
        path.relative_to(out).as_posix() + "/" for path in out.rglob("*")
        if path.is_dir() and path.relative_to(out).as_posix() != "entry"
    )
    if foreign:
        listed = ", ".join(foreign[:3]) + (f" and {len(foreign) - 3} more" if len(foreign) > 3 else "")
        raise ZendarError(
            f"output {shown!r} holds files the export did not write ({listed}): move them away or render "
            "into another folder"
        )


def _write_site(store: Store, site: Path) -> list[str]:
    """Every file of the export inside the (new, empty) folder ``site``; returns their relative paths."""
    (site / "entry").mkdir(mode=PUBLISHED_FOLDER_MODE)
    for folder in (site, site / "entry"):
        os.chmod(folder, PUBLISHED_FOLDER_MODE)
    board = ranking.leaderboard(store)
    files: dict[str, bytes] = {}
    for entry in board["entries"]:
        found = ranking.entry_parts(store, entry["id"])
        if found is None:  # hidden or deleted since the ranking was read
            continue
        files[f"entry/{entry['id']}.html"] = entry_page(*found, static=True, root="../").encode()
    files["leaderboard.json"] = orjson.dumps(board, option=orjson.OPT_INDENT_2)
    files["leaderboard.csv"] = ranking.to_csv(board).encode()
    files["index.html"] = ranking_page(board, entry_href=lambda i: f"entry/{i}.html", static=True).encode()
    for name, data in files.items():
        write_bytes_atomic(site / name, data, mode=PUBLISHED_MODE)
    manifest = {"generator": "zendar-leaderboard render", "files": sorted(files)}
    write_bytes_atomic(site / MANIFEST_NAME, orjson.dumps(manifest, option=orjson.OPT_INDENT_2), mode=PUBLISHED_MODE)
    return list(files)


def _sync_folder(folder: Path) -> None:
    # The renames are durable only once the folder holding them is.
    handle = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    try:
        os.fsync(handle)
    finally:
        os.close(handle)


def render_site(store: Store, out: str | os.PathLike) -> list[Path]:
    """Rebuild the static leaderboard in ``out`` (created if missing) from the database alone.

    Raises
    ------
    ZendarError
        When ``out`` is not a folder, or holds files that no previous export wrote (nothing is
        changed).

    Returns
    -------
    list of Path
        The files of the site (its manifest aside).
    """
    shown = str(out)
    out = Path(out).resolve()  # a symbolic link to the published folder: swap the folder itself
    if out.exists() and not out.is_dir():
        raise ZendarError(f"output {shown!r} exists and is not a folder")
    if not out.parent.is_dir():
        raise ZendarError(f"the folder of output {shown!r} does not exist")
    if out.exists():
        _previous_export(out, shown)
    remove_stale_temporaries(out.parent, out.name)
    site = temporary_sibling(out)
    try:
        site.mkdir(mode=PUBLISHED_FOLDER_MODE)
        names = _write_site(store, site)
        if not out.exists():
            os.rename(site, out)
            forget(site)
        elif _exchange(site, out):
            pass  # ``site`` now holds the previous export, removed below
        else:
            # Without an atomic exchange: the previous export steps aside for the instant of one rename.
            previous = temporary_sibling(out)
            os.rename(out, previous)
            os.rename(site, out)
            forget(site)
            site = previous
        _sync_folder(out.parent)
    finally:
        remove_temporary(site)
    return [out / name for name in names]
