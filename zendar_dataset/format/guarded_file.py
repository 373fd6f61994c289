"""The file an HDF5 store is written through: a failed write never reaches HDF5.

When a write fails (disk full, quota, I/O error), HDF5 frees part of the
file's state while failing to close it, and the next close or the garbage
collector dereferences the freed memory: the process dies of a segmentation
fault (h5py issue 914, still present with HDF5 2.0).  So stores are created
through h5py's file-object driver with :class:`GuardedFile`, which records
the first OS error, reports success to HDF5 for everything after it (the
bytes are dropped: the file is a temporary that is removed anyway), and
raises the recorded error from :meth:`GuardedFile.raise_if_failed` and
:meth:`GuardedFile.close`, where Python code can handle it.

A Ctrl-C that lands while HDF5 calls into this file would be such a failure
too, so it is held back the same way: the interrupted system call is redone
and the ``KeyboardInterrupt`` raised by the next :meth:`raise_if_failed`.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import TypeVar

_T = TypeVar("_T")


class GuardedFile:
    """A binary file for ``h5py.File(fileobj)`` that keeps OS errors and interrupts away from HDF5.

    Parameters
    ----------
    path
        File to create; it must not exist (``"x+b"``).
    """

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = os.fspath(path)
        # Unbuffered: with a buffer, a seek or read would flush pending bytes and fail there.
        self._file = open(self.path, "x+b", buffering=0)
        self.error: OSError | None = None
        self._interrupt: BaseException | None = None

    def _record(self, exc: OSError) -> None:
        if self.error is None:
            # Name the file: the error of a raw write carries no filename.
            self.error = OSError(exc.errno, exc.strerror or str(exc), self.path)

    def _complete(self, call: Callable[[], _T]) -> _T:
        # An interrupted system call did nothing (EINTR, PEP 475): redo it, raise the interrupt later.
        while True:
            try:
                return call()
            except KeyboardInterrupt as exc:
                self._interrupt = self._interrupt or exc

    def seek(self, offset: int, whence: int = 0) -> int:
        return self._complete(lambda: self._file.seek(offset, whence))

    def tell(self) -> int:
        return self._complete(self._file.tell)

    def read(self, size: int = -1) -> bytes:
        return self._complete(lambda: self._file.read(size))

    def readinto(self, buffer) -> int:
        return self._complete(lambda: self._file.readinto(buffer))

    def write(self, data) -> int:
        view = memoryview(data).cast("B")
        size = view.nbytes
        if self.error is None:
            try:
                while view.nbytes:  # a raw write may take only part
                    view = view[self._complete(lambda: self._file.write(view)) :]
                return size
            except OSError as exc:
                self._record(exc)
        self.seek(view.nbytes, os.SEEK_CUR)
        return size

    def truncate(self, size: int | None = None) -> int:
        if self.error is None:
            try:
                return self._complete(lambda: self._file.truncate(size))
            except OSError as exc:
                self._record(exc)
        return self.tell() if size is None else size

    def flush(self) -> None:
        # Unbuffered: nothing is held here; HDF5 calls this at its own flush points.
        return None

    def raise_if_failed(self) -> None:
        """Raise a held-back Ctrl-C, then the first OS error of a write (the content is then incomplete)."""
        if self._interrupt is not None:
            interrupt, self._interrupt = self._interrupt, None
            raise interrupt
        if self.error is not None:
            raise self.error

    def close(self) -> None:
        """Close the file; raise a held-back Ctrl-C or the first OS error of any write (once)."""
        if not self._file.closed:
            try:
                self._complete(self._file.close)
            except OSError as exc:
                self._record(exc)
        error, self.error = self.error, None
        self.raise_if_failed()
        if error is not None:
            raise error
