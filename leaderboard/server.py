"""The HTTP server: JSON API, HTML pages and the upload form (standard library ``http.server``).

Routes (docs/leaderboard.md): ``POST /api/submissions``, ``GET /api/submissions/ID``,
``GET /api/leaderboard``, ``GET /``, ``GET /entry/ID``, ``GET /submit``, ``GET /leaderboard.json``,
``GET /leaderboard.csv``.

An upload is refused before its body is read when the token is missing or wrong (401), the declared
``Content-Length`` is missing (411) or over the limit (413), the round is closed (403) or the team's
quota is used (429). Otherwise the body is read and checked whole (422 with every problem), then
recorded and queued (202). Nothing in a request is ever used as a file name: the server reads only
the labels and database it was started with.
"""

from __future__ import annotations

import logging
import re
import secrets
import threading
from dataclasses import dataclass
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any
from urllib.parse import parse_qs, urlsplit

import orjson

from zendar_dataset.eval.protocol import ALL_BAND
from zendar_leaderboard import entries as entries_mod
from zendar_leaderboard.ground_truth import TestSplit
from zendar_leaderboard.pages import entry_page, ranking_page, submit_page
from zendar_leaderboard.scheduler import ScoringService
from zendar_leaderboard.scoring import BANDS
from zendar_leaderboard.store import QuotaExceeded, RoundClosed, Store, Team
from zendar_leaderboard.submission import check_submission

# ASCII digits only: str.isdigit() also accepts '²', which int() then refuses.
_CONTENT_LENGTH = re.compile(r"[0-9]{1,15}")
#: How long an upload waits for a checking slot before the server answers 503.
UPLOAD_SLOT_WAIT_S = 30.0

log = logging.getLogger("zendar_leaderboard")

#: At most this many problems are listed in a 422 answer, each at most PROBLEM_CHARS long.
MAX_PROBLEMS = 1000
PROBLEM_CHARS = 300


@dataclass
class ServerSettings:
    """What the request handlers need.

    Attributes
    ----------
    store
        The database.
    test_split
        The hidden labels (only their frame ids are used here, to check uploads).
    scoring
        The background scoring service (woken on each upload), or None.
    quota
        Submissions per team per rolling 30 days.
    max_bytes
        Largest accepted body.
    parallel_checks
        Uploads checked at the same time; more wait their turn. A parsed submission takes several
        times its size in memory, so this bounds the server's memory to a few uploads' worth.
    """

    store: Store
    test_split: TestSplit
    scoring: ScoringService | None
    quota: int
    max_bytes: int
    parallel_checks: int = 2

    def __post_init__(self) -> None:
        self.gt_frame_ids = list(self.test_split.frames)
        self.check_slots = threading.BoundedSemaphore(self.parallel_checks)


def _shape_problems(problems: list[str]) -> list[str]:
    shown = [p if len(p) <= PROBLEM_CHARS else p[: PROBLEM_CHARS - 3] + "..." for p in problems[:MAX_PROBLEMS]]
    if len(problems) > MAX_PROBLEMS:
        shown.append(f"... and {len(problems) - MAX_PROBLEMS} more problems")
    return shown


class Handler(BaseHTTPRequestHandler):
    """One request. ``self.server.settings`` is the :class:`ServerSettings`."""

    server_version = "zendar-leaderboard"
    sys_version = ""
    timeout = 60  # seconds a client may stay silent (a stalled upload cannot hold a thread for ever)

    @property
    def settings(self) -> ServerSettings:
        return self.server.settings  # type: ignore[attr-defined]

    def log_message(self, format: str, *args: Any) -> None:
        log.info("%s %s", self.address_string(), format % args)

    # Answers -------------------------------------------------------------------------------

    def _send(self, status: int, body: bytes, content_type: str, headers: dict[str, str] | None = None) -> None:
        self.send_response(status)
        self.send_header("Content-Type", content_type)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("X-Content-Type-Options", "nosniff")
        self.send_header("Cache-Control", "no-store")
        for name, value in (headers or {}).items():
            self.send_header(name, value)
        self.end_headers()
        if self.command != "HEAD":
            self.wfile.write(body)

    def _json(self, status: int, document: Any, headers: dict[str, str] | None = None) -> None:
        self._send(status, orjson.dumps(document), "application/json", headers)

    def _error(self, status: int, message: str, **extra: Any) -> None:
        headers = {"WWW-Authenticate": "Bearer"} if status == HTTPStatus.UNAUTHORIZED else None
        self._json(status, {"error": message, **extra}, headers)

    def _html(self, render: Any) -> None:
        nonce = secrets.token_urlsafe(16)
        csp = (
            f"default-src 'none'; script-src 'nonce-{nonce}'; style-src 'nonce-{nonce}'; "
            "connect-src 'self'; img-src 'self' data:; form-action 'self'; base-uri 'none'; frame-ancestors 'none'"
        )
        self._send(HTTPStatus.OK, render(nonce).encode(), "text/html; charset=utf-8", {"Content-Security-Policy": csp})

    # Authentication and limits ---------------------------------------------------------------

    def _team(self) -> Team | None:
        match = re.fullmatch(r"Bearer\s+(\S{1,200})", self.headers.get("Authorization", "").strip())
        return None if match is None else self.settings.store.team_for_token(match.group(1))

    def _upload_refusal(self) -> tuple[Team | None, int | None]:
        """Checks that need no body: answers the request and returns (None, None) on refusal."""
        team = self._team()
        if team is None:
            self._error(HTTPStatus.UNAUTHORIZED, "missing or wrong token (send 'Authorization: Bearer TOKEN')")
            return None, None
        declared = self.headers.get("Content-Length")
        if declared is None:
            self._error(HTTPStatus.LENGTH_REQUIRED, "a Content-Length header is required")
            return None, None
        if not _CONTENT_LENGTH.fullmatch(declared.strip()):
            self._error(HTTPStatus.BAD_REQUEST, "Content-Length must be a number of bytes")
            return None, None
        length = int(declared)
        if length > self.settings.max_bytes:
            self._error(
                HTTPStatus.REQUEST_ENTITY_TOO_LARGE,
                f"the submission is {length:,} bytes, over the limit of {self.settings.max_bytes:,} bytes",
            )
            return None, None
        store = self.settings.store
        if store.round_closed():
            self._error(HTTPStatus.FORBIDDEN, "the round is closed: submissions are not taken")
            return None, None
        if store.submissions_in_window(team.id) >= self.settings.quota:
            self._quota_error(team)
            return None, None
        return team, length

    def _quota_error(self, team: Team) -> None:
        self._error(
            HTTPStatus.TOO_MANY_REQUESTS,
            f"team {team.name!r} has used its {self.settings.quota} submissions of the last 30 days",
        )

    def handle_expect_100(self) -> bool:
        # A client that waits for "100 Continue" learns of a refusal before sending anything.
        if self.command == "POST" and urlsplit(self.path).path == "/api/submissions":
            team, _ = self._upload_refusal()
            if team is None:
                self.close_connection = True
                return False
        return super().handle_expect_100()

    # Routes --------------------------------------------------------------------------------

    def do_POST(self) -> None:
        self.close_connection = True  # the body of a refused upload is never read
        if urlsplit(self.path).path != "/api/submissions":
            self._error(HTTPStatus.NOT_FOUND, "no such resource")
            return
        team, length = self._upload_refusal()
        if team is None:
            return
        # A slot is taken before the body is read: uploads held in memory at once are bounded by the
        # slots, not by how many connections a client opens.
        if not self.settings.check_slots.acquire(timeout=UPLOAD_SLOT_WAIT_S):
            self._error(HTTPStatus.SERVICE_UNAVAILABLE, "the server is busy checking other uploads; try again shortly")
            return
        try:
            body = self.rfile.read(length)
            if len(body) != length:
                self._error(HTTPStatus.BAD_REQUEST, f"the body ended after {len(body):,} of {length:,} bytes")
                return
            checked = check_submission(body, self.settings.gt_frame_ids)
            if checked.ok:
                checked.document = None  # only the bytes are kept
        finally:
            self.settings.check_slots.release()
        if not checked.ok:
            n = len(checked.problems)
            self._error(
                HTTPStatus.UNPROCESSABLE_ENTITY,
                f"{n} problem{'s' if n != 1 else ''} in the submission; nothing was queued",
                problems=_shape_problems(checked.problems),
            )
            return
        try:
            submission_id = self.settings.store.add_submission(team, body, checked.sha256, checked.meta, self.settings.quota)
        except QuotaExceeded:
            self._quota_error(team)
            return
        except RoundClosed as exc:
            self._error(HTTPStatus.FORBIDDEN, str(exc))
            return
        if self.settings.scoring is not None:
            self.settings.scoring.wake()
        self._json(HTTPStatus.ACCEPTED, {"id": submission_id, "status": "queued"})

    def do_HEAD(self) -> None:
        self.do_GET()

    def do_GET(self) -> None:
        url = urlsplit(self.path)
        path, query = url.path, parse_qs(url.query)
        sort = query.get("sort", [ALL_BAND])[0]
        band = sort if sort in BANDS else ALL_BAND
        store = self.settings.store
        if path == "/api/leaderboard":
            self._json(HTTPStatus.OK, entries_mod.leaderboard(store, band))
        elif path == "/leaderboard.json":
            self._json(HTTPStatus.OK, entries_mod.leaderboard(store, band))
        elif path == "/leaderboard.csv":
            text = entries_mod.to_csv(entries_mod.leaderboard(store, band))
            self._send(HTTPStatus.OK, text.encode(), "text/csv; charset=utf-8")
        elif path in ("/", "/index.html"):
            page = _ranking_html(store, band)
            self._html(lambda nonce: page.replace(_NONCE_SLOT, nonce))
        elif path == "/submit":
            self._html(lambda nonce: submit_page(quota=self.settings.quota, max_bytes=self.settings.max_bytes, nonce=nonce))
        elif (match := re.fullmatch(r"/entry/(\d{1,18})", path)) is not None:
            self._entry(int(match.group(1)))
        elif (match := re.fullmatch(r"/api/submissions/(\d{1,18})", path)) is not None:
            self._status(int(match.group(1)))
        else:
            self._error(HTTPStatus.NOT_FOUND, "no such resource")

    def _entry(self, submission_id: int) -> None:
        store = self.settings.store
        found = entry_parts(store, submission_id)
        if found is None:
            self._error(HTTPStatus.NOT_FOUND, f"no entry {submission_id} on the leaderboard")
            return
        entry, parts = found
        self._html(lambda nonce: entry_page(entry, parts, static=False, nonce=nonce))

    def _status(self, submission_id: int) -> None:
        team = self._team()
        if team is None:
            self._error(HTTPStatus.UNAUTHORIZED, "missing or wrong token (send 'Authorization: Bearer TOKEN')")
            return
        store = self.settings.store
        submission = store.submission(submission_id)
        if submission is None or submission.team_id != team.id:  # another team's ids are not confirmed
            self._error(HTTPStatus.NOT_FOUND, f"no submission {submission_id} of team {team.name!r}")
            return
        answer: dict[str, Any] = {"id": submission.id, "status": submission.status}
        if submission.status == "queued":
            answer["position"] = store.queue_position(submission.id)
        if submission.status == "scored":
            score = store.score(submission.id)
            closed = store.round_closed()
            part = (score.private if closed and score.private else score.public) or {}
            answer["ap"] = part.get("ap", {band: None for band in BANDS})
            if part.get("ci"):
                answer["ci"] = part["ci"]
            answer["part"] = "private" if closed and score.private else "public"
        if submission.status == "failed":
            answer["error"] = submission.error
        answer["submitted_at"] = entries_mod.iso_utc(submission.submitted_at)
        answer["sha256"] = submission.sha256
        self._json(HTTPStatus.OK, answer)


# The ranking page is rendered once per database generation with this unguessable stand-in for
# the per-response nonce, which each response then puts in its place.
_NONCE_SLOT = secrets.token_hex(16)
_page_cache: dict[tuple[str, str], tuple[int, str]] = {}


def _ranking_html(store: Store, band: str) -> str:
    key = (str(store.path), band)
    generation = store.generation()
    cached = _page_cache.get(key)
    if cached is None or cached[0] != generation:
        board = entries_mod.leaderboard(store, band)
        page = ranking_page(board, entry_href=lambda i: f"/entry/{i}", static=False, nonce=_NONCE_SLOT)
        cached = _page_cache[key] = (generation, page)
    return cached[1]


def entry_parts(store: Store, submission_id: int) -> tuple[dict, dict[str, dict | None]] | None:
    """An entry shown on the leaderboard and its per-part scores (private only once closed)."""
    submission = store.submission(submission_id)
    if submission is None or submission.hidden or submission.status != "scored":
        return None
    score = store.score(submission_id)
    closed = store.round_closed()
    entry = entries_mod.entry_dict(submission, score, closed)
    parts = {"public": score.public}
    if closed:
        parts["private"] = score.private
    return entry, parts


class LeaderboardHTTPServer(ThreadingHTTPServer):
    """A threading server that carries the :class:`ServerSettings`."""

    daemon_threads = True
    request_queue_size = 128  # 50 readers connecting at once must not overflow the listen backlog

    def __init__(self, address: tuple[str, int], settings: ServerSettings) -> None:
        self.settings = settings
        super().__init__(address, Handler)
