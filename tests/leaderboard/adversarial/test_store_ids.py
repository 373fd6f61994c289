"""A deleted submission's score cannot land on another team's: ids are never reused, and a score
is recorded against the submission's id and the SHA-256 of the bytes it was computed from."""

from __future__ import annotations

import hashlib
import sqlite3

from tests.leaderboard.conftest import meta
from zendar_leaderboard.store import Store, Team

SCORES = {"public": {"ap": {"all": 1.0}}, "private": {"ap": {"all": 1.0}}, "protocol_name": "p",
          "protocol_version": "1", "evaluator_version": "1", "gt_sha256": "0" * 64}


def upload(store: Store, token: str, body: bytes) -> tuple[int, str]:
    sha256 = hashlib.sha256(body).hexdigest()
    return store.add_submission(store.team_for_token(token), body, sha256, meta(), quota=10), sha256


def test_the_id_of_a_deleted_newest_submission_is_not_given_again(tmp_path):
    store = Store(tmp_path / "board.db")
    token = store.add_team("a")
    first, _ = upload(store, token, b"first")
    store.delete(first)
    second, _ = upload(store, token, b"second")
    assert second != first


def test_a_score_finished_after_its_submission_was_deleted_does_not_land_on_the_next_upload(tmp_path):
    # Two scorer slots: A's perfect file is being scored by the first when the administrator
    # deletes it; team B's junk upload is then claimed by the second slot.
    store = Store(tmp_path / "board.db")
    token_a, token_b = store.add_team("team A"), store.add_team("team B")
    a_id, a_sha = upload(store, token_a, b"A's perfect predictions")
    assert store.claim_next() == a_id
    store.delete(a_id)
    b_id, b_sha = upload(store, token_b, b"B's junk")
    assert store.claim_next() == b_id

    assert not store.record_score(a_id, a_sha, SCORES)  # the first slot finishes A's file
    assert store.score(b_id) is None
    assert store.submission(b_id).status == "scoring" and store.submission(b_id).sha256 == b_sha
    assert store.scored_entries() == []


def test_a_score_of_other_bytes_than_the_submissions_is_not_recorded(tmp_path):
    store = Store(tmp_path / "board.db")
    token = store.add_team("a")
    submission_id, sha256 = upload(store, token, b"mine")
    assert store.claim_next() == submission_id
    assert not store.record_score(submission_id, hashlib.sha256(b"someone else's").hexdigest(), SCORES)
    assert store.score(submission_id) is None and store.submission(submission_id).status == "scoring"
    assert store.record_score(submission_id, sha256, SCORES)
    assert store.score(submission_id).submission_sha256 == sha256


# The submissions table as stores created before ids were made permanent have it.
OLD_SCHEMA = """
CREATE TABLE teams (id INTEGER PRIMARY KEY, name TEXT NOT NULL UNIQUE, token_sha256 TEXT NOT NULL UNIQUE,
                    created_at REAL NOT NULL);
CREATE TABLE submissions (
    id INTEGER PRIMARY KEY,
    team_id INTEGER NOT NULL REFERENCES teams(id) ON DELETE CASCADE,
    submitted_at REAL NOT NULL,
    status TEXT NOT NULL CHECK (status IN ('queued', 'scoring', 'scored', 'failed')),
    sha256 TEXT NOT NULL, meta TEXT NOT NULL, error TEXT, hidden INTEGER NOT NULL DEFAULT 0,
    scoring_runs INTEGER NOT NULL DEFAULT 0, interruptions INTEGER NOT NULL DEFAULT 0,
    started_at REAL, finished_at REAL
);
CREATE INDEX submissions_status ON submissions(status, id);
CREATE INDEX submissions_team ON submissions(team_id, submitted_at);
CREATE TABLE bodies (submission_id INTEGER PRIMARY KEY REFERENCES submissions(id) ON DELETE CASCADE,
                     body BLOB NOT NULL);
CREATE TABLE scores (submission_id INTEGER PRIMARY KEY REFERENCES submissions(id) ON DELETE CASCADE,
                     submission_sha256 TEXT NOT NULL, protocol_name TEXT NOT NULL, protocol_version TEXT NOT NULL,
                     evaluator_version TEXT NOT NULL, gt_sha256 TEXT NOT NULL, public TEXT, private TEXT,
                     scored_at REAL NOT NULL);
CREATE TABLE settings (key TEXT PRIMARY KEY, value TEXT NOT NULL);
INSERT INTO settings VALUES ('generation', '7');
INSERT INTO teams VALUES (1, 'old team', 'x', 0), (2, 'other team', 'y', 0);
INSERT INTO submissions (id, team_id, submitted_at, status, sha256, meta, hidden, scoring_runs)
    VALUES (1, 1, 10, 'scored', 'sha-1', '{"method": "one"}', 0, 1),
           (2, 2, 20, 'failed', 'sha-2', '{"method": "two"}', 1, 1),
           (3, 1, 30, 'queued', 'sha-3', '{"method": "three"}', 0, 0);
INSERT INTO bodies VALUES (1, x'01'), (2, x'02'), (3, x'03');
INSERT INTO scores VALUES (1, 'sha-1', 'p', '1', '1', 'g', '{"ap": 1}', '{"ap": 0.5}', 11);
"""


def test_a_store_of_the_old_layout_keeps_its_rows_and_no_longer_reuses_ids(tmp_path):
    path = tmp_path / "board.db"
    with sqlite3.connect(path) as connection:
        connection.executescript(OLD_SCHEMA)
    connection.close()

    store = Store(path)
    rows = store.submissions()
    assert [(r.id, r.team, r.status, r.sha256, r.meta["method"], r.hidden, r.counts_for_quota) for r in rows] == [
        (1, "old team", "scored", "sha-1", "one", False, True),
        (2, "other team", "failed", "sha-2", "two", True, True),
        (3, "old team", "queued", "sha-3", "three", False, True),
    ]
    assert [store.body(i) for i in (1, 2, 3)] == [b"\x01", b"\x02", b"\x03"]
    assert store.score(1).public == {"ap": 1} and store.score(1).private == {"ap": 0.5}
    assert store.generation() > 7

    store.delete(3)
    fourth = store.add_submission(Team(1, "old team"), b"new", "sha-4", meta(), quota=10)
    assert fourth == 4
    store.delete(1)  # foreign keys still cascade from the rebuilt table
    assert store.body(1) is None and store.score(1) is None

    reopened = Store(path)  # a second open finds nothing to migrate
    assert [r.id for r in reopened.submissions()] == [2, 4]
