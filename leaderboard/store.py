"""SQLite records of teams, submissions and scores (WAL mode, one transaction per change).

A submission row and its bytes are written in one transaction, and a score together with the
status ``scored`` in another, so each is recorded whole or not at all. Tokens are kept only as
SHA-256 hashes (a token is 256 random bits: a plain hash cannot be searched backwards).
"""

from __future__ import annotations

import hashlib
import json
import secrets
import sqlite3
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from zendar_dataset.errors import ZendarError

ROLLING_WINDOW_S = 30 * 86_400
#: A submission whose scoring was cut short by a server stop this many times is marked failed.
MAX_INTERRUPTIONS = 3

_SCHEMA = """
CREATE TABLE IF NOT EXISTS teams (
    id INTEGER PRIMARY KEY,
    name TEXT NOT NULL UNIQUE,
    token_sha256 TEXT NOT NULL UNIQUE,
    created_at REAL NOT NULL
);
CREATE TABLE IF NOT EXISTS submissions (
    id INTEGER PRIMARY KEY,
    team_id INTEGER NOT NULL REFERENCES teams(id) ON DELETE CASCADE,
    submitted_at REAL NOT NULL,
    status TEXT NOT NULL CHECK (status IN ('queued', 'scoring', 'scored', 'failed')),
    sha256 TEXT NOT NULL,
    meta TEXT NOT NULL,
    error TEXT,
    hidden INTEGER NOT NULL DEFAULT 0,
    scoring_runs INTEGER NOT NULL DEFAULT 0,
    interruptions INTEGER NOT NULL DEFAULT 0,
    started_at REAL,
    finished_at REAL
);
CREATE INDEX IF NOT EXISTS submissions_status ON submissions(status, id);
CREATE INDEX IF NOT EXISTS submissions_team ON submissions(team_id, submitted_at);
CREATE TABLE IF NOT EXISTS bodies (
    submission_id INTEGER PRIMARY KEY REFERENCES submissions(id) ON DELETE CASCADE,
    body BLOB NOT NULL
);
CREATE TABLE IF NOT EXISTS scores (
    submission_id INTEGER PRIMARY KEY REFERENCES submissions(id) ON DELETE CASCADE,
    submission_sha256 TEXT NOT NULL,
    protocol_name TEXT NOT NULL,
    protocol_version TEXT NOT NULL,
    evaluator_version TEXT NOT NULL,
    gt_sha256 TEXT NOT NULL,
    public TEXT,
    private TEXT,
    scored_at REAL NOT NULL
);
CREATE TABLE IF NOT EXISTS settings (key TEXT PRIMARY KEY, value TEXT NOT NULL);
INSERT OR IGNORE INTO settings (key, value) VALUES ('generation', '0');
"""


def token_hash(token: str) -> str:
    """Hex SHA-256 of a team token (what the store keeps)."""
    return hashlib.sha256(token.encode()).hexdigest()


@dataclass(frozen=True)
class Team:
    id: int
    name: str


@dataclass(frozen=True)
class SubmissionRow:
    """One submission as recorded (times are UNIX seconds, UTC)."""

    id: int
    team_id: int
    team: str
    submitted_at: float
    status: str
    sha256: str
    meta: dict
    error: str | None
    hidden: bool
    scoring_runs: int


@dataclass(frozen=True)
class ScoreRow:
    """A submission's shown scores and what they were computed under."""

    submission_id: int
    submission_sha256: str
    protocol_name: str
    protocol_version: str
    evaluator_version: str
    gt_sha256: str
    public: dict | None
    private: dict | None
    scored_at: float


class QuotaExceeded(ZendarError):
    """The team has used its submissions of the rolling window."""


class RoundClosed(ZendarError):
    """The round is closed: its private scores are shown and no submission is taken."""


class Store:
    """The leaderboard's database. Safe to share between threads (a connection per thread).

    Parameters
    ----------
    path
        The SQLite file; created with its tables when missing (unless ``read_only``).
    read_only
        Open an existing database for reading only (the scorer process: only the server writes).
    """

    def __init__(self, path: str | Path, *, read_only: bool = False) -> None:
        self.path = Path(path)
        self.read_only = read_only
        self._local = threading.local()
        if not self.path.parent.is_dir():
            raise ZendarError(f"database folder {str(self.path.parent)!r} does not exist")
        if read_only:
            self._connection()  # a missing or unreadable file fails here, not at the first read
        else:
            self._connection().executescript(_SCHEMA)  # idempotent; runs in its own transaction

    def _connection(self) -> sqlite3.Connection:
        db = getattr(self._local, "db", None)
        if db is None:
            target, uri = (f"file:{self.path}?mode=ro", True) if self.read_only else (self.path, False)
            db = sqlite3.connect(target, uri=uri, timeout=30.0, isolation_level=None, check_same_thread=False)
            db.row_factory = sqlite3.Row
            if not self.read_only:
                db.execute("PRAGMA journal_mode=WAL")
                db.execute("PRAGMA synchronous=FULL")
                db.execute("PRAGMA foreign_keys=ON")
            self._local.db = db
        return db

    class _Transaction:
        def __init__(self, db: sqlite3.Connection) -> None:
            self.db = db

        def __enter__(self) -> sqlite3.Connection:
            # IMMEDIATE takes the write lock up front: two writers never deadlock upgrading a read.
            self.db.execute("BEGIN IMMEDIATE")
            return self.db

        def __exit__(self, exc_type, exc, tb) -> None:
            if exc_type:
                self.db.execute("ROLLBACK")
                return
            # Every change, from this process or an administrator's command, moves the generation
            # on: readers cache what they built from the database until it moves.
            self.db.execute("UPDATE settings SET value = CAST(value AS INTEGER) + 1 WHERE key = 'generation'")
            self.db.execute("COMMIT")

    def _transaction(self) -> _Transaction:
        return Store._Transaction(self._connection())

    def generation(self) -> int:
        """A number that changes whenever anything in the database changes."""
        return int(self._connection().execute("SELECT value FROM settings WHERE key = 'generation'").fetchone()[0])

    def close(self) -> None:
        db = getattr(self._local, "db", None)
        if db is not None:
            db.close()
            self._local.db = None

    # Teams ---------------------------------------------------------------------------------

    def add_team(self, name: str) -> str:
        """Register a team; returns its token (shown once, never stored)."""
        if not name.strip() or len(name) > 100:
            raise ZendarError(f"team name must be 1 to 100 characters, got {len(name.strip())}")
        token = secrets.token_urlsafe(32)
        try:
            with self._transaction() as db:
                db.execute(
                    "INSERT INTO teams (name, token_sha256, created_at) VALUES (?, ?, ?)",
                    (name, token_hash(token), time.time()),
                )
        except sqlite3.IntegrityError:
            raise ZendarError(f"a team named {name!r} already exists in {str(self.path)!r}") from None
        return token

    def team_for_token(self, token: str) -> Team | None:
        row = self._connection().execute(
            "SELECT id, name FROM teams WHERE token_sha256 = ?", (token_hash(token),)
        ).fetchone()
        return None if row is None else Team(row["id"], row["name"])

    # Round ---------------------------------------------------------------------------------

    def round_closed(self) -> bool:
        row = self._connection().execute("SELECT value FROM settings WHERE key = 'round_closed'").fetchone()
        return row is not None and row["value"] == "1"

    def close_round(self) -> None:
        with self._transaction() as db:
            db.execute("INSERT OR REPLACE INTO settings (key, value) VALUES ('round_closed', '1')")

    # Submissions ---------------------------------------------------------------------------

    def submissions_in_window(self, team_id: int, now: float | None = None) -> int:
        """Submissions of the team in the rolling 30 days (queued, scoring, scored or failed)."""
        now = time.time() if now is None else now
        return self._connection().execute(
            "SELECT COUNT(*) FROM submissions WHERE team_id = ? AND submitted_at > ?",
            (team_id, now - ROLLING_WINDOW_S),
        ).fetchone()[0]

    def add_submission(self, team: Team, body: bytes, sha256: str, meta: dict, quota: int) -> int:
        """Record a valid submission as queued, with its bytes; returns its id.

        Raises
        ------
        QuotaExceeded
            When the team already has ``quota`` submissions in the rolling window (checked in the
            same transaction as the insert, so concurrent uploads cannot overrun it).
        RoundClosed
            When the round is closed.
        """
        now = time.time()
        with self._transaction() as db:
            if db.execute("SELECT value FROM settings WHERE key = 'round_closed'").fetchone() is not None:
                raise RoundClosed("the round is closed: submissions are not taken")
            used = db.execute(
                "SELECT COUNT(*) FROM submissions WHERE team_id = ? AND submitted_at > ?",
                (team.id, now - ROLLING_WINDOW_S),
            ).fetchone()[0]
            if used >= quota:
                raise QuotaExceeded(
                    f"team {team.name!r} has used its {quota} submissions of the last 30 days"
                )
            cursor = db.execute(
                "INSERT INTO submissions (team_id, submitted_at, status, sha256, meta) VALUES (?, ?, 'queued', ?, ?)",
                (team.id, now, sha256, json.dumps(meta)),
            )
            submission_id = cursor.lastrowid
            db.execute("INSERT INTO bodies (submission_id, body) VALUES (?, ?)", (submission_id, body))
        return submission_id

    def _row(self, row: sqlite3.Row) -> SubmissionRow:
        return SubmissionRow(
            id=row["id"], team_id=row["team_id"], team=row["team"], submitted_at=row["submitted_at"],
            status=row["status"], sha256=row["sha256"], meta=json.loads(row["meta"]), error=row["error"],
            hidden=bool(row["hidden"]), scoring_runs=row["scoring_runs"],
        )

    def submission(self, submission_id: int) -> SubmissionRow | None:
        row = self._connection().execute(
            "SELECT s.*, t.name AS team FROM submissions s JOIN teams t ON t.id = s.team_id WHERE s.id = ?",
            (submission_id,),
        ).fetchone()
        return None if row is None else self._row(row)

    def submissions(self) -> list[SubmissionRow]:
        rows = self._connection().execute(
            "SELECT s.*, t.name AS team FROM submissions s JOIN teams t ON t.id = s.team_id ORDER BY s.id"
        ).fetchall()
        return [self._row(r) for r in rows]

    def body(self, submission_id: int) -> bytes | None:
        row = self._connection().execute(
            "SELECT body FROM bodies WHERE submission_id = ?", (submission_id,)
        ).fetchone()
        return None if row is None else bytes(row["body"])

    def queue_position(self, submission_id: int) -> int | None:
        """1 for the next to be scored; None unless queued."""
        row = self._connection().execute(
            "SELECT status FROM submissions WHERE id = ?", (submission_id,)
        ).fetchone()
        if row is None or row["status"] != "queued":
            return None
        return self._connection().execute(
            "SELECT COUNT(*) FROM submissions WHERE status = 'queued' AND id <= ?", (submission_id,)
        ).fetchone()[0]

    def set_hidden(self, submission_id: int, hidden: bool) -> None:
        with self._transaction() as db:
            if db.execute("UPDATE submissions SET hidden = ? WHERE id = ?", (int(hidden), submission_id)).rowcount == 0:
                raise ZendarError(f"no submission {submission_id} in {str(self.path)!r}")

    def delete(self, submission_id: int) -> None:
        with self._transaction() as db:
            if db.execute("DELETE FROM submissions WHERE id = ?", (submission_id,)).rowcount == 0:
                raise ZendarError(f"no submission {submission_id} in {str(self.path)!r}")

    # Scoring -------------------------------------------------------------------------------

    def recover(self, protocol_version: str, gt_sha256: str) -> dict[str, int]:
        """Prepare the queue when a server starts.

        Submissions left in ``scoring`` by a server that stopped go back to the queue (marked
        failed after ``MAX_INTERRUPTIONS``); scores computed under another protocol version or
        other labels are queued for scoring again.

        Returns
        -------
        dict
            ``{"requeued": n, "gave_up": n, "rescore": n}``.
        """
        with self._transaction() as db:
            db.execute("UPDATE submissions SET interruptions = interruptions + 1 WHERE status = 'scoring'")
            gave_up = db.execute(
                "UPDATE submissions SET status = 'failed', finished_at = ?, error = ? "
                "WHERE status = 'scoring' AND interruptions >= ?",
                (time.time(), f"scoring was interrupted {MAX_INTERRUPTIONS} times by server stops", MAX_INTERRUPTIONS),
            ).rowcount
            requeued = db.execute("UPDATE submissions SET status = 'queued' WHERE status = 'scoring'").rowcount
            rescore = db.execute(
                "UPDATE submissions SET status = 'queued' WHERE status = 'scored' AND id IN "
                "(SELECT submission_id FROM scores WHERE protocol_version != ? OR gt_sha256 != ?)",
                (protocol_version, gt_sha256),
            ).rowcount
        return {"requeued": requeued, "gave_up": gave_up, "rescore": rescore}

    def claim_next(self) -> int | None:
        """Move the oldest queued submission to ``scoring`` and return its id (None: queue empty)."""
        with self._transaction() as db:
            row = db.execute("SELECT id FROM submissions WHERE status = 'queued' ORDER BY id LIMIT 1").fetchone()
            if row is None:
                return None
            db.execute(
                "UPDATE submissions SET status = 'scoring', started_at = ?, scoring_runs = scoring_runs + 1 WHERE id = ?",
                (time.time(), row["id"]),
            )
        return row["id"]

    def release(self, submission_id: int) -> None:
        """Put a submission being scored back in the queue (the server is stopping)."""
        with self._transaction() as db:
            db.execute("UPDATE submissions SET status = 'queued' WHERE id = ? AND status = 'scoring'", (submission_id,))

    def record_score(self, submission_id: int, sha256: str, scores: dict[str, Any]) -> bool:
        """Store the score and mark the submission scored, in one transaction.

        Returns False (and stores nothing) when the submission is no longer being scored (deleted).
        """
        with self._transaction() as db:
            updated = db.execute(
                "UPDATE submissions SET status = 'scored', finished_at = ?, error = NULL WHERE id = ? AND status = 'scoring'",
                (time.time(), submission_id),
            ).rowcount
            if updated:
                db.execute(
                    "INSERT OR REPLACE INTO scores (submission_id, submission_sha256, protocol_name, protocol_version, "
                    "evaluator_version, gt_sha256, public, private, scored_at) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    (
                        submission_id, sha256, scores["protocol_name"], scores["protocol_version"],
                        scores["evaluator_version"], scores["gt_sha256"],
                        json.dumps(scores["public"]), json.dumps(scores["private"]), time.time(),
                    ),
                )
        return bool(updated)

    def record_failure(self, submission_id: int, reason: str) -> None:
        """Mark a submission failed with a reason meant for its team."""
        with self._transaction() as db:
            db.execute(
                "UPDATE submissions SET status = 'failed', finished_at = ?, error = ? WHERE id = ? AND status = 'scoring'",
                (time.time(), reason, submission_id),
            )

    def score(self, submission_id: int) -> ScoreRow | None:
        row = self._connection().execute("SELECT * FROM scores WHERE submission_id = ?", (submission_id,)).fetchone()
        return None if row is None else self._score_row(row)

    @staticmethod
    def _score_row(row: sqlite3.Row) -> ScoreRow:
        return ScoreRow(
            submission_id=row["submission_id"], submission_sha256=row["submission_sha256"],
            protocol_name=row["protocol_name"], protocol_version=row["protocol_version"],
            evaluator_version=row["evaluator_version"], gt_sha256=row["gt_sha256"],
            public=json.loads(row["public"]), private=json.loads(row["private"]), scored_at=row["scored_at"],
        )

    def scored_entries(self) -> list[tuple[SubmissionRow, ScoreRow]]:
        """Scored, not hidden submissions with their scores, in submission order."""
        rows = self._connection().execute(
            "SELECT s.*, t.name AS team, c.submission_id, c.submission_sha256, c.protocol_name, c.protocol_version, "
            "c.evaluator_version, c.gt_sha256, c.public, c.private, c.scored_at "
            "FROM submissions s JOIN teams t ON t.id = s.team_id JOIN scores c ON c.submission_id = s.id "
            "WHERE s.status = 'scored' AND s.hidden = 0 ORDER BY s.id"
        ).fetchall()
        return [(self._row(r), self._score_row(r)) for r in rows]
