"""Decoding a stream's next records on a second thread while the writer stores the current one.

The column decoders are numba functions that release the GIL (``nogil``), and the writer spends its
time in file writes, compression and waits on zarr's event loop, which release it too: with the
decoding one record ahead, the two overlap on two cores instead of taking turns.  :class:`ReadAhead`
starts at once, so a stream can also be decoded while the writer is still busy with earlier ones.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Iterator
from typing import Generic, TypeVar

T = TypeVar("T")

#: Records decoded ahead at most: enough to keep the decoder busy through a slow write, few enough that
#: the decoded sweeps and frames waiting (a few MB each) stay small.
READ_AHEAD_RECORDS = 2

_DONE = object()


class ReadAhead(Generic[T]):
    """``records`` in their order, produced on a background thread, started now, up to ``depth`` ahead.

    Parameters
    ----------
    records : iterator
        Consumed on the background thread only (its side effects, e.g. a stream summary's counts,
        happen there, each before its record is handed over).
    depth : int
        Records waiting at most.

    Iterating yields each item of ``records``; an exception ``records`` raises is raised there, after the
    items before it. :meth:`close` (also on leaving a ``with`` block) stops the thread after the record it
    is decoding, closes ``records`` and returns once the thread has ended.
    """

    def __init__(self, records: Iterator[T], depth: int = READ_AHEAD_RECORDS) -> None:
        self._records = records
        self._waiting: queue.Queue = queue.Queue(maxsize=max(1, int(depth)))
        self._stop = threading.Event()
        self._ended = False
        self._thread = threading.Thread(target=self._produce, name="zendar-read-ahead", daemon=True)
        try:
            self._thread.start()
        except BaseException:  # a Ctrl-C right after the start still stops the thread
            self.close()
            raise

    def _hand_over(self, item: object) -> bool:
        while not self._stop.is_set():
            try:
                self._waiting.put(item, timeout=0.05)
                return True
            except queue.Full:
                continue
        return False

    def _produce(self) -> None:
        try:
            for item in self._records:
                if not self._hand_over((item, None)):
                    return
            self._hand_over((_DONE, None))
        except BaseException as exc:  # handed to the caller, which raises it in its own thread
            self._hand_over((None, exc))
        finally:
            close = getattr(self._records, "close", None)
            if close is not None:
                close()

    def __iter__(self) -> "ReadAhead[T]":
        return self

    def __next__(self) -> T:
        if self._ended:
            raise StopIteration
        item, error = self._waiting.get()
        if error is not None:
            self._ended = True
            raise error
        if item is _DONE:
            self._ended = True
            raise StopIteration
        return item

    def close(self) -> None:
        self._ended = True
        self._stop.set()
        if self._thread.ident is not None:
            self._thread.join()

    def __enter__(self) -> "ReadAhead[T]":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def read_ahead(records: Iterator[T], depth: int = READ_AHEAD_RECORDS) -> Iterator[T]:
    """``records`` through a :class:`ReadAhead` started at the first ``next`` and closed when the caller
    stops (at the end, on an exception or ``close``): the caller returns only once the thread has ended."""
    with ReadAhead(records, depth) as ahead:
        yield from ahead
