"""An idle server does not write: polling an empty queue is a read."""

from __future__ import annotations

import hashlib
import os
import sqlite3

from tests.leaderboard.conftest import meta
from zendar_leaderboard.store import Store


def test_polling_an_empty_queue_writes_nothing_to_the_database(tmp_path):
    path = tmp_path / "board.db"
    store = Store(path)
    observer = sqlite3.connect(path)  # data_version moves whenever another connection commits

    def state() -> tuple[int, int, int]:
        return (observer.execute("PRAGMA data_version").fetchone()[0], os.stat(f"{path}-wal").st_size,
                store.generation())

    before = state()
    for _ in range(10):  # ten idle polls, one a second in a server
        assert store.claim_next() is None
    assert state() == before

    team = store.team_for_token(store.add_team("t"))
    submission_id = store.add_submission(team, b"{}", hashlib.sha256(b"{}").hexdigest(), meta(), quota=3)
    queued = state()
    assert queued != before  # the observer sees a write when there is one
    assert store.claim_next() == submission_id
    assert state() != queued
    observer.close()
