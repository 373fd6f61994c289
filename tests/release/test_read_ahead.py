"""The importer's read-ahead: same items in the same order, errors where they happened, no thread left behind."""

from __future__ import annotations

import threading
import time

import pytest

from zendar_dataset.release.read_ahead import ReadAhead, read_ahead


def test_items_come_in_order_from_another_thread():
    producers = []

    def records():
        for k in range(50):
            producers.append(threading.get_ident())
            yield k

    assert list(read_ahead(records(), depth=3)) == list(range(50))
    assert set(producers) and threading.get_ident() not in set(producers)


def test_an_error_is_raised_after_the_items_before_it():
    def records():
        yield 1
        yield 2
        raise ValueError("record 3 does not decode")

    seen = []
    with pytest.raises(ValueError, match="record 3"):
        for item in read_ahead(records()):
            seen.append(item)
    assert seen == [1, 2]


def test_it_decodes_ahead_while_the_caller_works():
    produced = []

    def records():
        for k in range(4):
            produced.append(k)
            yield k

    items = read_ahead(records(), depth=2)
    assert next(items) == 0
    deadline = time.monotonic() + 5.0
    while len(produced) < 3 and time.monotonic() < deadline:
        time.sleep(0.01)
    # Item 0 taken, 1 and 2 waiting in the queue: three decoded before the caller asked for the next.
    assert produced == [0, 1, 2]
    assert list(items) == [1, 2, 3]


def test_stopping_early_closes_the_source_and_ends_the_thread():
    closed = threading.Event()

    def records():
        try:
            k = 0
            while True:
                yield k
                k += 1
        finally:
            closed.set()

    before = threading.active_count()
    items = read_ahead(records(), depth=2)
    assert [next(items) for _ in range(3)] == [0, 1, 2]
    items.close()
    assert closed.is_set()
    assert threading.active_count() == before


def test_an_error_in_the_caller_ends_the_thread():
    def records():
        yield from range(1000)

    before = threading.active_count()
    with pytest.raises(RuntimeError):
        for item in read_ahead(records()):
            if item == 5:
                raise RuntimeError("the writer failed")
    assert threading.active_count() == before


def test_a_read_ahead_decodes_before_it_is_asked_and_closes_when_left():
    produced, closed = [], threading.Event()

    def records():
        try:
            for k in range(10):
                produced.append(k)
                yield k
        finally:
            closed.set()

    before = threading.active_count()
    with ReadAhead(records(), depth=3) as ahead:
        deadline = time.monotonic() + 5.0
        while len(produced) < 4 and time.monotonic() < deadline:
            time.sleep(0.01)
        # Three waiting and the fourth decoded, held until there is room: nothing asked for yet.
        assert produced == [0, 1, 2, 3]
        assert next(ahead) == 0
    assert closed.is_set()
    assert threading.active_count() == before
    with pytest.raises(StopIteration):
        next(ahead)
