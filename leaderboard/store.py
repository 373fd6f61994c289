"""SQLite records of teams, submissions and scores (WAL mode, one transaction per change).

A submission row and its bytes are written in one transaction, and a score together with the
status ``scored`` in another, so each is recorded whole or not at all. Tokens are kept only as
SHA-256 hashes (a token is 256 random bits: a plain hash cannot be searched backwards).

Submission ids are never reused (``AUTOINCREMENT``), and a score is recorded only against the id
*and* the SHA-256 of the bytes it was computed from. The database and its WAL and shared-memory
files are readable by their owner only: they hold every team's predictions and contacts. A write
that fails for a reason of the machine's (the write lock held past the busy timeout, a full disk)
raises :class:`StoreUnavailable`. One server per database: :func:`lock_for_serving`.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import logging
import os
import secrets
import sqlite3
import stat
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from zendar_dataset.errors import ZendarError
from zendar_leaderboard.names import team_name

log = logging.getLogger("zendar_leaderboard")

ROLLING_WINDOW_S = 30 * 86_400
#: A submission whose scoring was cut short by a server stop this many times is marked failed.
MAX_INTERRUPTIONS = 3
#: SQLite's largest INTEGER (64-bit signed): no submission id is above it.
MAX_SUBMISSION_ID = 2**63 - 1
#: Seconds a write waits for another connection's write lock before it fails as unavailable.
BUSY_TIMEOUT_S = 30.0
#: Owner read and write only: the files hold every team's predictions, contacts and private scores.
FILE_MODE = 0o600
#: What a team reads when its submission failed for a reason of the server's, not of its file.
NOT_CHARGED = "this submission does not count against the team's quota: submit it again"
INFRASTRUCTURE_FAILURE = f"scoring failed on the server's side (its database could not be used); {NOT_CHARGED}"

_SUBMISSIONS_TABLE = """
CREATE TABLE IF NOT EXISTS {name} (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
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
    finished_at REAL,
    counts_for_quota INTEGER NOT NULL DEFAULT 1
);
"""
_SUBMISSIONS_COLUMNS = (
    "id", "team_id", "submitted_at", "status", "sha256", "meta", "error", "hidden", "scoring_runs",
    "interruptions", "started_at", "finished_at", "counts_for_quota",
)
_INDEXES = """
CREATE INDEX IF NOT EXISTS submissions_status ON submissions(status, id);
CREATE INDEX IF NOT EXISTS submissions_team ON submissions(team_id, submitted_at);
"""
_SCHEMA = """
CREATE TABLE IF NOT EXISTS teams (
    id INTEGER PRIMARY KEY,
    name TEXT NOT NULL UNIQUE,
    token_sha256 TEXT NOT NULL UNIQUE,
    created_at REAL NOT NULL
);
""" + _SUBMISSIONS_TABLE.format(name="submissions") + _INDEXES + """
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


_COUNTED_IN_WINDOW = (
    "SELECT COUNT(*) FROM submissions WHERE team_id = ? AND submitted_at > ? AND counts_for_quota = 1"
)
_OLDEST_QUEUED = "SELECT id FROM submissions WHERE status = 'queued' ORDER BY id LIMIT 1"


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
    counts_for_quota: bool


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


class StoreUnavailable(sqlite3.OperationalError):
    """A change could not be written for a reason of the machine's, not of the request.

    The write lock was held by another connection past :data:`BUSY_TIMEOUT_S`, the disk was full,
    or the disk failed. Still an ``sqlite3.OperationalError``, so whatever handles database errors
    handles this one; nothing of the change was recorded.
    """


class StoreInUse(ZendarError):
    """Another server holds the database (see :func:`lock_for_serving`)."""


def lock_path(db: str | Path) -> Path:
    """The lock file a server holds for its whole life: ``<db>.lock`` beside the database."""
    db = Path(db)
    return db.with_name(db.name + ".lock")


@contextlib.contextmanager
def lock_for_serving(db: str | Path) -> Iterator[None]:
    """Hold the database's server lock (an exclusive ``flock`` on ``<db>.lock``) for the block.

    Two servers on one database would each put the other's submission in progress back in the
    queue and score it twice; the lock is taken before anything else is read or written and the
    kernel drops it when the process ends, however it ends.

    Raises
    ------
    StoreInUse
        When another process holds it (nothing has been touched).
    """
    path = lock_path(db)
    descriptor = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, FILE_MODE)
    try:
        try:
            fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise StoreInUse(
                f"another server is already running on the database {str(db)!r} (it holds {str(path)!r}); "
                "stop it before starting this one"
            ) from None
        yield
    finally:
        os.close(descriptor)  # closing the last descriptor releases the lock


def _create_private(path: Path) -> None:
    """Create the database file owner-only (SQLite gives its WAL and shm files the same mode), or make
    an existing database and its companion files owner-only."""
    try:
        os.close(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, FILE_MODE))
        return
    except FileExistsError:
        pass
    for file in (path, Path(f"{path}-wal"), Path(f"{path}-shm")):
        try:
            if stat.S_IMODE(file.stat().st_mode) & 0o077:
                file.chmod(FILE_MODE)
        except FileNotFoundError:
            continue
        except PermissionError:
            log.warning("%s is readable by other users and is not ours to restrict (chmod 600 it)", file)


def _read_only_uri(path: Path) -> str:
    """``file:`` URI of ``path`` opened read-only; ``#``, ``?`` and ``%`` in the path are escaped."""
    return f"{path.resolve().as_uri()}?mode=ro"


def _tables(path: Path) -> set[str] | None:
    """The tables of the SQLite file ``path``, read without writing to it (None: no such file).

    Raises
    ------
    ZendarError
        When ``path`` is not a file or not an SQLite database.
    """
    if not path.exists():
        return None
    if not path.is_file():
        raise ZendarError(f"database {str(path)!r} is not a file")
    connection = sqlite3.connect(_read_only_uri(path), uri=True, timeout=BUSY_TIMEOUT_S)
    try:
        return {row[0] for row in connection.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
    except sqlite3.DatabaseError as exc:
        if exc.sqlite_errorname != "SQLITE_NOTADB":
            raise
        raise ZendarError(
            f"{str(path)!r} is not an SQLite database, so not a leaderboard database; it was left unchanged"
        ) from None
    finally:
        connection.close()


def _refuse_other_files(path: Path, *, existing: bool) -> None:
    """Refuse, before anything is written, a file that is not a leaderboard database.

    An empty file (or an SQLite database without tables) becomes one, unless ``existing`` asks for
    a database that already is one; another program's database is never given the leaderboard's
    tables.

    Raises
    ------
    ZendarError
        Naming the file; it is left as it was.
    """
    tables = _tables(path)
    if tables is None:
        if existing:
            raise ZendarError(f"no leaderboard database at {str(path)!r}")
        return
    if "teams" in tables:
        return
    if tables:
        shown = ", ".join(sorted(tables)[:3]) + (", ..." if len(tables) > 3 else "")
        raise ZendarError(
            f"{str(path)!r} is an SQLite database of something else (tables {shown}), not a leaderboard "
            "database; it was left unchanged"
        )
    if existing:
        raise ZendarError(f"{str(path)!r} is empty, not a leaderboard database; it was left unchanged")


class Store:
    """The leaderboard's database. Safe to share between threads (a connection per thread).

    Parameters
    ----------
    path
        The SQLite file; created with its tables when missing or empty (unless ``read_only`` or
        ``existing``).
    read_only
        Open an existing database for reading only (the scorer process: only the server writes).
    existing
        Refuse a path that is not already a leaderboard database (missing, or an empty file)
        instead of creating the tables: the administrator's commands on a database they name.

    Raises
    ------
    ZendarError
        When ``path`` is another kind of file, or another program's SQLite database (left as it was).
    """

    def __init__(self, path: str | Path, *, read_only: bool = False, existing: bool = False) -> None:
        self.path = Path(path)
        self.read_only = read_only
        self._local = threading.local()
        if not self.path.parent.is_dir():
            raise ZendarError(f"database folder {str(self.path.parent)!r} does not exist")
        if read_only:
            self._connection()  # a missing or unreadable file fails here, not at the first read
        else:
            _refuse_other_files(self.path, existing=existing)
            _create_private(self.path)
            self._connection().executescript(_SCHEMA)  # idempotent; runs in its own transaction
            self._migrate()

    def _connection(self) -> sqlite3.Connection:
        db = getattr(self._local, "db", None)
        if db is None:
            target, uri = (_read_only_uri(self.path), True) if self.read_only else (self.path, False)
            db = sqlite3.connect(
                target, uri=uri, timeout=BUSY_TIMEOUT_S, isolation_level=None, check_same_thread=False
            )
            db.row_factory = sqlite3.Row
            if not self.read_only:
                db.execute("PRAGMA journal_mode=WAL")
                db.execute("PRAGMA synchronous=FULL")
                db.execute("PRAGMA foreign_keys=ON")
            self._local.db = db
        return db

    @contextlib.contextmanager
    def _transaction(self) -> Iterator[sqlite3.Connection]:
        """One write transaction; a machine-side failure anywhere in it raises :class:`StoreUnavailable`."""
        db = self._connection()
        try:
            # IMMEDIATE takes the write lock up front: two writers never deadlock upgrading a read.
            db.execute("BEGIN IMMEDIATE")
            try:
                yield db
                # Every change, from this process or an administrator's command, moves the generation
                # on: readers cache what they built from the database until it moves.
                db.execute("UPDATE settings SET value = CAST(value AS INTEGER) + 1 WHERE key = 'generation'")
                db.execute("COMMIT")
            except BaseException:
                if db.in_transaction:  # SQLite may have rolled back already (a full disk does)
                    db.execute("ROLLBACK")
                raise
        except sqlite3.OperationalError as exc:
            if isinstance(exc, StoreUnavailable):
                raise
            raise StoreUnavailable(f"the database could not record the change: {exc}") from exc

    def _migrate(self) -> None:
        """Rebuild a ``submissions`` table of an older layout (ids that could be reused, no quota flag).

        SQLite cannot add ``AUTOINCREMENT`` to a table, so the rows move to a new table in one
        transaction with foreign keys off (dropping the old table must not cascade to the bodies
        and scores, which keep referring to ``submissions`` by name), as SQLite documents.
        """
        db = self._connection()

        def outdated() -> list[str] | None:
            sql = db.execute(
                "SELECT sql FROM sqlite_master WHERE type = 'table' AND name = 'submissions'"
            ).fetchone()[0]
            columns = [row["name"] for row in db.execute("PRAGMA table_info(submissions)")]
            return columns if "AUTOINCREMENT" not in sql.upper() or set(_SUBMISSIONS_COLUMNS) - set(columns) else None

        if outdated() is None:
            return
        db.execute("PRAGMA foreign_keys=OFF")  # a no-op inside a transaction: set before it
        try:
            with self._transaction():
                columns = outdated()  # another process may have migrated meanwhile
                if columns is None:
                    return
                kept = ", ".join(c for c in _SUBMISSIONS_COLUMNS if c in columns)
                db.execute("DROP TABLE IF EXISTS submissions_migrating")
                db.execute(_SUBMISSIONS_TABLE.format(name="submissions_migrating"))
                db.execute(f"INSERT INTO submissions_migrating ({kept}) SELECT {kept} FROM submissions")
                db.execute("DROP TABLE submissions")
                db.execute("ALTER TABLE submissions_migrating RENAME TO submissions")
                for statement in _INDEXES.strip().split(";")[:-1]:
                    db.execute(statement)
                if db.execute("PRAGMA foreign_key_check").fetchone() is not None:
                    raise ZendarError(f"the database {str(self.path)!r} has broken references; it was left unchanged")
            log.warning("database %s: submissions table rebuilt (ids are no longer reused)", self.path)
        finally:
            db.execute("PRAGMA foreign_keys=ON")

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
        """Register a team under its normalised name; returns its token (shown once, never stored).

        The name rules and the look-alike check are :func:`zendar_leaderboard.names.team_name`'s
        (:class:`~zendar_leaderboard.names.NameRefused`); checked in the insert's transaction.
        """
        # Hexadecimal: a URL-safe token may start with "-", which a command line reads as an option
        # (`submit --token -x…` failed for one team in 64).
        token = secrets.token_hex(32)
        try:
            with self._transaction() as db:
                existing = [row[0] for row in db.execute("SELECT name FROM teams")]
                db.execute(
                    "INSERT INTO teams (name, token_sha256, created_at) VALUES (?, ?, ?)",
                    (team_name(name, existing), token_hash(token), time.time()),
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
        """Submissions of the team in the rolling 30 days that count against its quota (queued,
        scoring, scored, or failed for a reason of the submission's)."""
        now = time.time() if now is None else now
        return self._connection().execute(_COUNTED_IN_WINDOW, (team_id, now - ROLLING_WINDOW_S)).fetchone()[0]

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
            used = db.execute(_COUNTED_IN_WINDOW, (team.id, now - ROLLING_WINDOW_S)).fetchone()[0]
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
            counts_for_quota=bool(row["counts_for_quota"]),
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
        failed after ``MAX_INTERRUPTIONS``, not counted against the team's quota: the stops were
        the server's); scores computed under another protocol version or
        other labels are queued for scoring again.

        Returns
        -------
        dict
            ``{"requeued": n, "gave_up": n, "rescore": n}``.
        """
        with self._transaction() as db:
            db.execute("UPDATE submissions SET interruptions = interruptions + 1 WHERE status = 'scoring'")
            gave_up = db.execute(
                "UPDATE submissions SET status = 'failed', finished_at = ?, error = ?, counts_for_quota = 0 "
                "WHERE status = 'scoring' AND interruptions >= ?",
                (time.time(), f"scoring was interrupted {MAX_INTERRUPTIONS} times by server stops; {NOT_CHARGED}",
                 MAX_INTERRUPTIONS),
            ).rowcount
            requeued = db.execute("UPDATE submissions SET status = 'queued' WHERE status = 'scoring'").rowcount
            rescore = db.execute(
                "UPDATE submissions SET status = 'queued' WHERE status = 'scored' AND id IN "
                "(SELECT submission_id FROM scores WHERE protocol_version != ? OR gt_sha256 != ?)",
                (protocol_version, gt_sha256),
            ).rowcount
        return {"requeued": requeued, "gave_up": gave_up, "rescore": rescore}

    def claim_next(self) -> int | None:
        """Move the oldest queued submission to ``scoring`` and return its id (None: queue empty).

        An empty queue is seen with a read alone: an idle server polls without writing to disk.
        """
        if self._connection().execute(_OLDEST_QUEUED).fetchone() is None:
            return None
        with self._transaction() as db:
            row = db.execute(_OLDEST_QUEUED).fetchone()  # another slot may have claimed it meanwhile
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

        ``sha256`` is that of the bytes the score was computed from: it must be the submission's.
        Returns False (and stores nothing) when the submission is no longer being scored (deleted)
        or holds other bytes.
        """
        with self._transaction() as db:
            updated = db.execute(
                "UPDATE submissions SET status = 'scored', finished_at = ?, error = NULL "
                "WHERE id = ? AND sha256 = ? AND status = 'scoring'",
                (time.time(), submission_id, sha256),
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

    def record_failure(self, submission_id: int, reason: str, *, counts_for_quota: bool = True) -> None:
        """Mark a submission failed with a reason meant for its team.

        ``counts_for_quota=False`` for a failure of the server's (its database, its stops): the
        submission then no longer counts against the team's quota.
        """
        with self._transaction() as db:
            db.execute(
                "UPDATE submissions SET status = 'failed', finished_at = ?, error = ?, counts_for_quota = ? "
                "WHERE id = ? AND status = 'scoring'",
                (time.time(), reason, int(counts_for_quota), submission_id),
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
