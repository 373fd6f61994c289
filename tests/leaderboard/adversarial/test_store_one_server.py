"""One server per database: a second ``serve`` on it exits 2 at once and touches nothing, and a
``serve`` that cannot get its port leaves the queue as it found it."""

from __future__ import annotations

import hashlib
import json
import socket
import sqlite3
import subprocess
import sys
import time

import pytest

from tests.leaderboard.conftest import ground_truth, ground_truth_file, meta, start_server, submission
from tests.leaderboard.helpers import post_submission, wait_done
from zendar_leaderboard.store import Store

SERVE = [sys.executable, "-m", "zendar_leaderboard.cli", "serve"]


def serve(db, gt, port: int) -> subprocess.CompletedProcess:
    return subprocess.run(SERVE + ["--gt", str(gt), "--db", str(db), "--host", "127.0.0.1", "--port", str(port)],
                          capture_output=True, text=True, timeout=300)


def interruptions(db, submission_id: int) -> int:
    """How many times a server start found the submission in ``scoring`` and put it back in the queue."""
    with sqlite3.connect(db) as connection:
        row = connection.execute("SELECT interruptions FROM submissions WHERE id = ?", (submission_id,)).fetchone()
    connection.close()
    return row[0]


@pytest.mark.slow
def test_second_serves_on_a_database_being_served_exit_2_and_leave_its_scoring_alone(tmp_path):
    gt, gt_path = ground_truth_file(tmp_path, n_scenes=8, frames_per_scene=10)
    db = tmp_path / "board.db"
    store = Store(db)
    token = store.add_team("first come")
    # 100,000 resamples make the scoring last seconds: the second servers start in the middle of it.
    first = start_server(db, gt_path, "--bootstrap", "100000")
    try:
        status, answer = post_submission(first.url, token, submission(gt))
        assert status == 202
        deadline = time.monotonic() + 120
        while store.submission(answer["id"]).status != "scoring":
            assert time.monotonic() < deadline, "scoring never started"
            time.sleep(0.05)
        port = int(first.url.rsplit(":", 1)[1])
        for _ in range(3):
            second = serve(db, gt_path, port)
            assert second.returncode == 2, second.stderr
            assert "another server is already running on the database" in second.stderr
            assert "Traceback" not in second.stderr
        assert interruptions(db, answer["id"]) == 0
        done = wait_done(first.url, token, answer["id"], timeout_s=300)
        assert done["status"] == "scored"
    finally:
        first.stop()
    assert store.submission(answer["id"]).scoring_runs == 1


def test_a_serve_that_cannot_get_its_port_leaves_a_submission_in_progress_where_it_was(tmp_path):
    gt_path = tmp_path / "gt.json"
    gt_path.write_text(json.dumps(ground_truth()))
    db = tmp_path / "board.db"
    store = Store(db)
    team = store.team_for_token(store.add_team("left scoring"))
    submission_id = store.add_submission(team, b"{}", hashlib.sha256(b"{}").hexdigest(), meta(), quota=3)
    assert store.claim_next() == submission_id  # a server that was killed left it in scoring
    generation = store.generation()
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        completed = serve(db, gt_path, taken.getsockname()[1])
    assert completed.returncode == 1 and "cannot listen on" in completed.stderr
    assert store.submission(submission_id).status == "scoring"
    assert interruptions(db, submission_id) == 0
    assert store.generation() == generation  # nothing was written


def test_a_submission_given_up_after_three_server_stops_does_not_count_against_the_quota(tmp_path):
    store = Store(tmp_path / "board.db")
    team = store.team_for_token(store.add_team("stopped thrice"))
    submission_id = store.add_submission(team, b"{}", hashlib.sha256(b"{}").hexdigest(), meta(), quota=3)
    for _ in range(3):  # claimed, then the server stops before it is scored
        assert store.claim_next() == submission_id
        store.recover("protocol", "labels")
    row = store.submission(submission_id)
    assert row.status == "failed" and "does not count against the team's quota" in row.error
    assert store.submissions_in_window(team.id) == 0
