"""The database and its WAL and shared-memory files are readable by their owner only; so is a
server's lock file."""

from __future__ import annotations

import os
import sqlite3
import stat
from pathlib import Path

import pytest

from zendar_leaderboard.store import Store


@pytest.fixture
def open_umask():
    """The usual umask 022, under which files are created readable by everyone unless asked otherwise."""
    previous = os.umask(0o022)
    yield
    os.umask(previous)


def modes(path: Path) -> dict[str, int]:
    return {p.name: stat.S_IMODE(p.stat().st_mode) for p in sorted(path.parent.iterdir())}


def test_a_new_database_and_its_wal_and_shm_files_are_owner_only(tmp_path, open_umask):
    path = tmp_path / "board.db"
    store = Store(path)
    store.add_team("t")  # writes the WAL
    assert modes(path) == {"board.db": 0o600, "board.db-shm": 0o600, "board.db-wal": 0o600}


def test_an_existing_world_readable_database_is_made_owner_only_when_opened(tmp_path, open_umask):
    path = tmp_path / "board.db"
    Store(path).close()  # a leaderboard database (another program's is refused, untouched)
    connection = sqlite3.connect(path)
    connection.execute("INSERT INTO settings (key, value) VALUES ('k', 'v')")
    connection.commit()  # the connection stays open: its WAL and shm files stay on disk
    for file in tmp_path.iterdir():
        file.chmod(0o644)
    assert modes(path) == {"board.db": 0o644, "board.db-shm": 0o644, "board.db-wal": 0o644}
    Store(path)
    assert modes(path) == {"board.db": 0o600, "board.db-shm": 0o600, "board.db-wal": 0o600}
    connection.close()


def test_the_servers_lock_file_is_owner_only(tmp_path, open_umask):
    from zendar_leaderboard.store import lock_for_serving, lock_path

    path = tmp_path / "board.db"
    with lock_for_serving(path):
        assert stat.S_IMODE(lock_path(path).stat().st_mode) == 0o600
