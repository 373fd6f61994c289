"""The static export is readable by a web server running as another user, whatever the publisher's umask."""

from __future__ import annotations

import os
import stat

from zendar_leaderboard.export import render_site
from zendar_leaderboard.store import Store


def test_exported_files_are_0644_under_a_strict_umask(tmp_path):
    store = Store(tmp_path / "board.db")
    old = os.umask(0o077)
    try:
        written = render_site(store, tmp_path / "site")
    finally:
        os.umask(old)
    names = {path.name for path in written}
    assert {"index.html", "leaderboard.json", "leaderboard.csv"} <= names
    assert {stat.S_IMODE(os.stat(path).st_mode) for path in written} == {0o644}
