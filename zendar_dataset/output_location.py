"""Where an output may go: never inside a dataset or file that the same command reads."""

from __future__ import annotations

import os
import pathlib
from collections.abc import Callable

from zendar_dataset.errors import ZendarError

#: Entries an output folder's refusal names before "and N more".
NAMED_ENTRIES = 5


def _is_url(location: str | os.PathLike) -> bool:
    # As format.stores.is_url, without importing the storage backends.
    return "://" in str(location) and not str(location).startswith("file://")


def _resolved(location: str | os.PathLike) -> pathlib.Path:
    text = str(location)
    text = text[len("file://"):] if text.startswith("file://") else text
    # strict=False: the output usually does not exist yet; its existing ancestors' links are still resolved.
    return pathlib.Path(text).expanduser().resolve(strict=False)


def refuse_output_inside(
    output: str | os.PathLike,
    *,
    datasets: tuple[str | os.PathLike, ...] = (),
    files: tuple[str | os.PathLike, ...] = (),
    what: str = "output",
) -> None:
    """Raise when ``output`` is inside a dataset root being read, or is an input file.

    Links are resolved first, so a symlink into a dataset is caught too.

    Parameters
    ----------
    output
        Local path to be written (a file or a directory).
    datasets
        Dataset roots (or other input directories) the command reads; URLs are skipped.
    files
        Input files the command reads; ``output`` must not be one of them.
    what
        How the output is named in the message (``"OUT"``, ``"-o"``, ``"--out"``).

    Raises
    ------
    ZendarError
        Naming the output and the input it would write into.
    """
    target = _resolved(output)
    for root in datasets:
        if _is_url(root):
            continue
        base = _resolved(root)
        if target == base or base in target.parents:
            raise ZendarError(
                f"{what} {str(output)!r} is inside the dataset {str(root)!r} being read; "
                "write outputs outside the input dataset"
            )
    for source in files:
        if not _is_url(source) and _resolved(source) == target:
            raise ZendarError(f"{what} {str(output)!r} is the input file {str(source)!r}; choose another path")


__all__ = ["refuse_output_inside"]


def other_entries(folder: pathlib.Path, own: Callable[[pathlib.Path], bool] = lambda entry: False) -> str | None:
    """The entries of the folder ``folder`` that ``own`` does not claim, named for a refusal
    (``"a.txt, b, c and 3 more"``, sorted), or None when there are none.

    A command that writes into a folder it may find non-empty (a resume) refuses one holding anything
    else: what it would overwrite or mix with is the user's.
    """
    names = sorted(entry.name for entry in folder.iterdir() if not own(entry))
    if not names:
        return None
    more = len(names) - NAMED_ENTRIES
    return ", ".join(names[:NAMED_ENTRIES]) + (f" and {more} more" if more > 0 else "")
