"""Where an output may go: never inside a dataset or file that the same command reads."""

from __future__ import annotations

import os
import pathlib

from zendar_dataset.errors import ZendarError


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
