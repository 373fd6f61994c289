"""Decoding a stream's next records on a second thread while the writer stores the current one.

The column decoders are numba functions that release the GIL (``nogil``), and the writer spends its
time in file writes, compression and waits on zarr's event loop, which release it too: with the
decoding one record ahead, the two overlap on two cores instead of taking turns.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Iterator
from typing import TypeVar

T = TypeVar("T")

#: Records decoded ahead at most: enough to keep the decoder busy through a slow write, few enough that
#: the decoded sweeps and frames waiting (a few MB each) stay small.
READ_AHEAD_RECORDS = 2

_DONE = object()


def read_ahead(records: Iterator[T], depth: int = READ_AHEAD_RECORDS) -> Iterator[T]:
    """``records`` in their order, produced on a background thread up to ``depth`` ahead.

    Parameters
    ----------
    records : iterator
        Consumed on the background thread only (its side effects, e.g. a stream summary's counts,
        happen there, each before its record is yielded here).
    depth : int
        Records waiting at most.

    Yields
    ------
    Each item of ``records``. An exception ``records`` raises is raised here, after the items before
    it. When the caller stops early (an exception, ``close``), the thread stops after the record it is
    decoding and ``records`` is closed; the caller returns only once the thread has ended.
    """
    waiting: queue.Queue = queue.Queue(maxsize=depth)
    stop = threading.Event()

    def hand_over(item: object) -> bool:
        while not stop.is_set():
            try:
                waiting.put(item, timeout=0.05)
                return True
            except queue.Full:
                continue
        return False

    def produce() -> None:
        try:
            for item in records:
                if not hand_over((item, None)):
                    return
            hand_over((_DONE, None))
        except BaseException as exc:  # handed to the caller, which raises it in its own thread
            hand_over((None, exc))
        finally:
            close = getattr(records, "close", None)
            if close is not None:
                close()

    thread = threading.Thread(target=produce, name="zendar-read-ahead", daemon=True)
    try:
        thread.start()  # inside: a Ctrl-C right after it still stops the thread
        while True:
            item, error = waiting.get()
            if error is not None:
                raise error
            if item is _DONE:
                return
            yield item
    finally:
        stop.set()
        if thread.ident is not None:
            thread.join()
