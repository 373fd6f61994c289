"""A database whose path holds ``#``, ``?`` or ``%`` is scored like any other (the scorer's read-only
``file:`` URI escapes them)."""

from __future__ import annotations

from tests.leaderboard.conftest import InProcessServer, ground_truth, submission
from tests.leaderboard.helpers import post_submission, wait_done
from zendar_leaderboard.store import Store


def test_a_submission_is_scored_when_the_database_folder_is_named_with_uri_characters(tmp_path):
    folder = tmp_path / "board #1?mode=rw%20"
    folder.mkdir()
    board = InProcessServer(folder, ground_truth(), bootstrap=0)
    try:
        token = board.store.add_team("odd path")
        status, answer = post_submission(board.url, token, submission(ground_truth()))
        assert status == 202
        done = wait_done(board.url, token, answer["id"])
        assert done["status"] == "scored", done
    finally:
        board.stop()
    assert sorted(p.name for p in tmp_path.iterdir()) == [folder.name]  # no stray file beside the folder


def test_a_read_only_store_reads_a_database_named_with_uri_characters(tmp_path):
    path = tmp_path / "100% #sure?.db"
    store = Store(path)
    team = store.team_for_token(store.add_team("t"))
    submission_id = store.add_submission(team, b"bytes", "sha", {"method": "m"}, quota=3)
    assert Store(path, read_only=True).body(submission_id) == b"bytes"
