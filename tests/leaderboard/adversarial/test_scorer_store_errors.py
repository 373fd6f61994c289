"""Scoring goes on through database errors: a write lock held past the busy timeout, a full disk.

The scorer thread retries with doubling waits; a result that cannot be recorded ends as a failure
that is the server's (its team's quota untouched); an upload during the error answers 503.
"""

from __future__ import annotations

import hashlib
import json
import logging
import sqlite3
import threading
import time

import pytest

from tests.leaderboard.conftest import InProcessServer, ground_truth, ground_truth_file, submission
from tests.leaderboard.helpers import post_submission, request, wait_done
from zendar_leaderboard import scheduler, store as store_module
from zendar_leaderboard.ground_truth import load_test_split
from zendar_leaderboard.scheduler import ScorerSettings, ScoringService
from zendar_leaderboard.store import Store

DISK_FULL = "database or disk is full"


class FailingWrites:
    """Makes the store's statements that start with ``prefix`` raise a full disk, ``times`` times in all."""

    def __init__(self, store: Store, prefix: str, times: int) -> None:
        self.prefix = prefix
        self.remaining = times
        self._lock = threading.Lock()
        self._real_connection = store._connection

    def connection(self) -> _Connection:
        return _Connection(self, self._real_connection())

    def should_fail(self, sql: str) -> bool:
        with self._lock:
            if sql.startswith(self.prefix) and self.remaining > 0:
                self.remaining -= 1
                return True
            return False


class _Connection:
    def __init__(self, injection: FailingWrites, real: sqlite3.Connection) -> None:
        self._injection = injection
        self._real = real

    def execute(self, sql: str, *args):
        if self._injection.should_fail(sql):
            raise sqlite3.OperationalError(DISK_FULL)
        return self._real.execute(sql, *args)

    def __getattr__(self, name: str):
        return getattr(self._real, name)


def fail_writes(monkeypatch, store: Store, prefix: str, times: int) -> FailingWrites:
    injection = FailingWrites(store, prefix, times)
    monkeypatch.setattr(store, "_connection", injection.connection)
    return injection


@pytest.fixture
def quick_retries(monkeypatch):
    """Short waits between attempts and three attempts, so that a test sees them all."""
    monkeypatch.setattr(scheduler, "STORE_RETRY_WAIT_S", 0.05)
    monkeypatch.setattr(scheduler, "STORE_ATTEMPTS", 3)


@pytest.fixture
def quota_one_board(tmp_path, quick_retries):
    server = InProcessServer(tmp_path, ground_truth(), quota=1, bootstrap=0)
    yield server
    server.stop()


def test_a_write_lock_held_past_the_busy_timeout_delays_scoring_but_does_not_stop_it(tmp_path, monkeypatch, caplog,
                                                                                       quick_retries):
    monkeypatch.setattr(store_module, "BUSY_TIMEOUT_S", 0.2)
    gt, gt_path = ground_truth_file(tmp_path)
    test_split = load_test_split(gt_path)
    store = Store(tmp_path / "board.db")
    team = store.team_for_token(store.add_team("patient"))
    body = json.dumps(submission(gt)).encode()
    submission_id = store.add_submission(team, body, hashlib.sha256(body).hexdigest(), {"method": "m"}, quota=3)
    holder = sqlite3.connect(tmp_path / "board.db", isolation_level=None)
    holder.execute("BEGIN IMMEDIATE")  # another connection holds the write lock, as `sqlite3 board.db` can
    scoring = ScoringService(store, ScorerSettings(
        gt=str(gt_path), split=None, db=str(tmp_path / "board.db"), gt_sha256=test_split.sha256, bootstrap=0,
    ))
    caplog.set_level(logging.ERROR, logger="zendar_leaderboard")
    scoring.start()
    try:
        deadline = time.monotonic() + 120
        while sum("database is locked" in r.getMessage() for r in caplog.records) < 3:
            assert scoring._threads[0].is_alive(), "the scorer thread ended on the locked database"
            assert time.monotonic() < deadline, "the claim never met the lock three times"
            time.sleep(0.05)
        assert len(scoring._scorers) == 1  # the failed claims kept the slot's scorer, started no other
        holder.execute("ROLLBACK")
        deadline = time.monotonic() + 120
        while store.submission(submission_id).status != "scored":
            assert time.monotonic() < deadline, f"not scored: {store.submission(submission_id)}"
            time.sleep(0.05)
        assert scoring._threads[0].is_alive()
    finally:
        holder.close()
        scoring.stop()


def test_an_upload_while_another_connection_holds_the_write_lock_answers_503_with_a_reason(tmp_path, monkeypatch):
    monkeypatch.setattr(store_module, "BUSY_TIMEOUT_S", 0.2)
    board = InProcessServer(tmp_path, ground_truth(), bootstrap=0)
    try:
        token = board.store.add_team("locked out")
        holder = sqlite3.connect(board.db, isolation_level=None)
        holder.execute("BEGIN IMMEDIATE")
        try:
            status, answer = post_submission(board.url, token, submission(ground_truth()))
        finally:
            holder.execute("ROLLBACK")
            holder.close()
        assert status == 503 and "database is locked" in answer["error"] and "nothing was recorded" in answer["error"]
        assert board.store.submissions() == []
        status, answer = post_submission(board.url, token, submission(ground_truth()))
        assert status == 202
        assert wait_done(board.url, token, answer["id"])["status"] == "scored"
    finally:
        board.stop()


def test_an_upload_while_the_disk_is_full_answers_503_and_charges_nothing(quota_one_board, monkeypatch):
    board = quota_one_board
    token = board.store.add_team("full disk")
    fail_writes(monkeypatch, board.store, "INSERT INTO submissions", 1)
    status, answer = post_submission(board.url, token, submission(ground_truth()))
    assert status == 503 and DISK_FULL in answer["error"]
    assert board.store.submissions_in_window(board.store.team_for_token(token).id) == 0
    status, answer = post_submission(board.url, token, submission(ground_truth()))
    assert status == 202
    assert wait_done(board.url, token, answer["id"])["status"] == "scored"


def test_a_score_that_fails_to_record_twice_is_recorded_on_the_third_attempt(quota_one_board, monkeypatch):
    board = quota_one_board
    token = board.store.add_team("second time lucky")
    injection = fail_writes(monkeypatch, board.store, "UPDATE submissions SET status = 'scored'", 2)
    status, answer = post_submission(board.url, token, submission(ground_truth()))
    assert status == 202
    done = wait_done(board.url, token, answer["id"])
    assert done["status"] == "scored" and injection.remaining == 0
    assert board.store.submission(answer["id"]).scoring_runs == 1


def test_a_score_that_cannot_be_recorded_fails_as_the_servers_fault_and_the_queue_drains(quota_one_board, monkeypatch):
    board = quota_one_board
    token = board.store.add_team("unlucky")
    team_id = board.store.team_for_token(token).id
    fail_writes(monkeypatch, board.store, "UPDATE submissions SET status = 'scored'", scheduler.STORE_ATTEMPTS)
    status, first = post_submission(board.url, token, submission(ground_truth()))
    assert status == 202
    done = wait_done(board.url, token, first["id"])
    assert done["status"] == "failed"
    assert done["error"].startswith("scoring failed on the server's side")
    assert "does not count against the team's quota" in done["error"]
    assert board.store.submissions_in_window(team_id) == 0  # quota 1, and still free

    status, second = post_submission(board.url, token, submission(ground_truth(), seed=2))
    assert status == 202
    assert wait_done(board.url, token, second["id"])["status"] == "scored"
    status, third = post_submission(board.url, token, submission(ground_truth(), seed=3))
    assert status == 429  # a scored submission counts as before
    status, _ = request(f"{board.url}/api/submissions/{first['id']}", token=token)
    assert status == 200


def test_an_unexpected_error_in_the_scoring_loop_is_logged_and_scoring_goes_on(quota_one_board, monkeypatch, caplog):
    board = quota_one_board
    token = board.store.add_team("after the bug")
    real_claim = board.store.claim_next
    raised = []

    def claim_with_a_bug():
        if not raised:
            raised.append(True)
            raise RuntimeError("a bug in claiming")
        return real_claim()

    caplog.set_level(logging.ERROR, logger="zendar_leaderboard")
    monkeypatch.setattr(board.store, "claim_next", claim_with_a_bug)
    status, answer = post_submission(board.url, token, submission(ground_truth()))
    assert status == 202
    assert wait_done(board.url, token, answer["id"])["status"] == "scored"
    assert raised and any(r.exc_info and "a bug in claiming" in str(r.exc_info[1]) for r in caplog.records)
