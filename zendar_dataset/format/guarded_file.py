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
"""

from __future__ import annotations

import os


class GuardedFile:
    """A binary file for ``h5py.File(fileobj)`` that keeps OS errors away from HDF5.

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

    def _record(self, exc: OSError) -> None:
        if self.error is None:
            # Name the file: a buffered write's error carries no filename.
            self.error = OSError(exc.errno, exc.strerror or str(exc), self.path)

    def seek(self, offset: int, whence: int = 0) -> int:
        return self._file.seek(offset, whence)

    def tell(self) -> int:
        return self._file.tell()

    def read(self, size: int = -1) -> bytes:
        return self._file.read(size)

    def readinto(self, buffer) -> int:
        return self._file.readinto(buffer)

    def write(self, data) -> int:
        view = memoryview(data).cast("B")
        size = view.nbytes
        if self.error is None:
            try:
                while view.nbytes:  # a raw write may take only part
                    view = view[self._file.write(view) :]
                return size
            except OSError as exc:
                self._record(exc)
        self._file.seek(view.nbytes, os.SEEK_CUR)
        return size

    def truncate(self, size: int | None = None) -> int:
        if self.error is None:
            try:
                return self._file.truncate(size)
            except OSError as exc:
                self._record(exc)
        return self._file.tell() if size is None else size

    def flush(self) -> None:
        if self.error is None:
            try:
                self._file.flush()
            except OSError as exc:
                self._record(exc)

    def raise_if_failed(self) -> None:
        """Raise the first OS error of a write, if any (the file's content is then incomplete)."""
        if self.error is not None:
            raise self.error

    def close(self) -> None:
        """Close the file; raise the first OS error of any write (once)."""
        if not self._file.closed:
            try:
                self._file.close()
            except OSError as exc:
                self._record(exc)
        error, self.error = self.error, None
        if error is not None:
            raise error
