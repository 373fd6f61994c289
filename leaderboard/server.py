"""The HTTP server: its settings and state, and the request handler that answers from the route table.

What each URL answers is in :mod:`zendar_leaderboard.routes`; this module is the standard library's
``http.server`` around it. The server object carries the :class:`ServerSettings` and the
:class:`RankingCache`; nothing is kept in module globals.

What a client can hold is bounded: connections (in all and per client address), the time to send a
request's line and headers, the time to send an upload's body, uploads per team, and uploads
checked at once (the checking slots, taken only once an upload's headers pass). When the process
runs out of file descriptors the accept loop pauses instead of spinning.
"""

from __future__ import annotations

import errno
import logging
import re
import secrets
import socket
import threading
import time
from collections import Counter
from dataclasses import dataclass
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any
from urllib.parse import parse_qs, urlsplit

from zendar_dataset.eval.protocol import ALL_BAND
from zendar_leaderboard import ranking
from zendar_leaderboard.ground_truth import TestSplit
from zendar_leaderboard.pages import ranking_page
from zendar_leaderboard.routes import Answer, dispatch, error_answer
from zendar_leaderboard.scheduler import ScoringService
from zendar_leaderboard.scoring import BANDS
from zendar_leaderboard.store import Store

log = logging.getLogger("zendar_leaderboard")

#: The slowest upload the default body deadline allows for, in bytes per second (2 Mbit/s) ...
MIN_UPLOAD_BYTES_PER_S = 250_000
#: ... plus this much time for any upload.
UPLOAD_DEADLINE_FLOOR_S = 10.0
#: A refused upload's body up to this many times the size limit is read and dropped, so that a
#: client that sends its body before reading the answer still gets the answer.
DRAIN_LIMIT_FACTOR = 2
#: The accept loop's pause when the process has no file descriptor left.
ACCEPT_BACKOFF_S = 0.1
#: Refused connections and failed accepts are logged in one line at most this often.
REPORT_EVERY_S = 10.0
#: Answers logged even without --verbose: requests the server could not parse or that came too slowly.
ALWAYS_LOGGED = frozenset({400, 408, 414, 431, 505})
#: Why a request was refused, for the refusals the standard library sends without a reason.
ERROR_REASONS = {
    HTTPStatus.REQUEST_URI_TOO_LONG: "the request line is longer than 65,536 bytes",
    HTTPStatus.REQUEST_HEADER_FIELDS_TOO_LARGE: "the request headers are too large",
}

# C0 and C1 control characters, written as \xNN in the log: a request line must not drive the
# terminal that shows the log.
_CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f]")


def printable(text: str) -> str:
    """``text`` with its control characters written as ``\\xNN``."""
    return _CONTROL.sub(lambda match: f"\\x{ord(match.group()):02x}", text)


def default_upload_deadline_s(max_bytes: int) -> float:
    """Time to send the largest upload at :data:`MIN_UPLOAD_BYTES_PER_S`, plus a floor."""
    return UPLOAD_DEADLINE_FLOOR_S + max_bytes / MIN_UPLOAD_BYTES_PER_S


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
        Uploads checked at the same time (the checking slots); more wait their turn. Checking an
        upload takes up to 40 times its size in memory (the body included), so checks take at most
        ``parallel_checks * 40 * max_bytes``.
    parallel_receives
        Upload bodies received at the same time (the receiving slots, taken once an upload's
        headers pass); more wait their turn. A body waiting for its check holds its receiving slot,
        so bodies held at once take at most ``parallel_receives * max_bytes`` besides the checks.
    upload_deadline_s
        Time to send a whole upload body, from the moment its receiving slot is granted (None: the
        default, :func:`default_upload_deadline_s` of ``max_bytes``). A slower upload is answered
        408 and gives its slot back.
    uploads_per_team
        Uploads of one team received or checked at once; more are answered 429 at once.
    max_connections, max_connections_per_address
        Open connections in all and per client IP address; more are answered 503 and closed.
    header_timeout_s
        Time to send a request's line and headers, and the time an idle connection stays open.
    """

    store: Store
    test_split: TestSplit
    scoring: ScoringService | None
    quota: int
    max_bytes: int
    parallel_checks: int = 2
    parallel_receives: int = 8
    upload_deadline_s: float | None = None
    uploads_per_team: int = 1
    max_connections: int = 512
    max_connections_per_address: int = 64
    header_timeout_s: float = 10.0

    def __post_init__(self) -> None:
        self.gt_frame_ids = list(self.test_split.frames)
        self.check_slots = threading.BoundedSemaphore(self.parallel_checks)
        self.receive_slots = threading.BoundedSemaphore(self.parallel_receives)
        if self.upload_deadline_s is None:
            self.upload_deadline_s = default_upload_deadline_s(self.max_bytes)
        self._team_uploads: Counter[int] = Counter()
        self._team_uploads_lock = threading.Lock()

    def begin_team_upload(self, team_id: int) -> bool:
        """Count one more upload in progress for the team; False (nothing counted) when it has its share."""
        with self._team_uploads_lock:
            if self._team_uploads[team_id] >= self.uploads_per_team:
                return False
            self._team_uploads[team_id] += 1
            return True

    def end_team_upload(self, team_id: int) -> None:
        with self._team_uploads_lock:
            self._team_uploads[team_id] -= 1
            if not self._team_uploads[team_id]:
                del self._team_uploads[team_id]


class RankingCache:
    """The ranking per sort band, as data and as the live page, rebuilt when the database changes.

    Each is built once per database generation and band, then served from memory: readers cost a
    one-row query until something changes. The data is shared between requests and only read.

    Parameters
    ----------
    store
        The database.
    """

    def __init__(self, store: Store) -> None:
        self.store = store
        # The page is rendered with this unguessable stand-in for the per-response nonce, which
        # each response then puts in its place.
        self._nonce_slot = secrets.token_hex(16)
        self._boards: dict[str, tuple[int, dict[str, Any]]] = {}
        self._pages: dict[str, tuple[int, str]] = {}

    def board(self, band: str) -> dict[str, Any]:
        """:func:`zendar_leaderboard.ranking.leaderboard` sorted by ``band``."""
        return self._board(band, self.store.generation())

    def page(self, band: str, nonce: str) -> str:
        """The ranking page sorted by ``band``, its styles and script carrying ``nonce``."""
        generation = self.store.generation()
        cached = self._pages.get(band)
        if cached is None or cached[0] != generation:
            board = self._board(band, generation)
            page = ranking_page(board, entry_href=lambda i: f"/entry/{i}", static=False, nonce=self._nonce_slot)
            cached = self._pages[band] = (generation, page)
        return cached[1].replace(self._nonce_slot, nonce)

    def _board(self, band: str, generation: int) -> dict[str, Any]:
        cached = self._boards.get(band)
        if cached is None or cached[0] != generation:
            cached = self._boards[band] = (generation, ranking.leaderboard(self.store, band))
        return cached[1]


class Handler(BaseHTTPRequestHandler):
    """One connection's requests, each answered by :func:`zendar_leaderboard.routes.dispatch`.

    HTTP/1.1: persistent connections, and ``Expect: 100-continue`` answered by the upload view
    itself (100 Continue only once the upload's headers pass, otherwise the refusal at once).
    """

    server: LeaderboardHTTPServer
    server_version = "zendar-leaderboard"
    sys_version = ""
    protocol_version = "HTTP/1.1"
    timeout = 60  # seconds one read or write may wait; whole heads and bodies have shorter deadlines

    head_expired = False  # set by the server when the request line and headers came too slowly
    expects_continue = False
    body_read = False
    _error_reason = ""

    @property
    def band(self) -> str:
        """The band the ranking is sorted by: ``?sort=BAND``, ``all`` unless a known band."""
        sort = parse_qs(urlsplit(self.path).query).get("sort", [ALL_BAND])[0]
        return sort if sort in BANDS else ALL_BAND

    def handle(self) -> None:
        try:
            super().handle()
        finally:
            # This thread ends with the connection: its database connection must not outlive it.
            self.server.settings.store.close()

    def handle_one_request(self) -> None:
        self.head_expired = self.expects_continue = self.body_read = False
        self._error_reason = ""
        self.server.watch_head(self)
        try:
            super().handle_one_request()
        finally:
            self.server.head_done(self)

    def parse_request(self) -> bool:
        expired_before = self.head_expired
        parsed = not expired_before and super().parse_request()
        if self.server.head_done(self) and (expired_before or parsed):
            if expired_before:
                # The line was cut short and never parsed: set what the answer and its log line read.
                self.command = None
                self.request_version = self.protocol_version
                self.requestline = str(self.raw_requestline, "iso-8859-1").rstrip("\r\n")
            self.close_connection = True
            self.send_error(
                HTTPStatus.REQUEST_TIMEOUT,
                f"the request line and headers took longer than {self.server.settings.header_timeout_s:g} s",
            )
            return False
        return parsed

    def handle_expect_100(self) -> bool:
        # The upload view sends 100 Continue once it wants the body; any other answer is final.
        self.expects_continue = True
        return True

    def send_continue(self) -> None:
        """``100 Continue``, when the client waits for it before sending the body."""
        if self.expects_continue:
            self.send_response_only(HTTPStatus.CONTINUE)
            self.end_headers()

    def read_body(self, length: int, deadline_s: float) -> bytes:
        """The body's ``length`` bytes, all within ``deadline_s`` (fewer when the client closes first).

        Raises
        ------
        TimeoutError
            When the deadline passes first.
        """
        self.body_read = True
        body = bytearray(length)
        view = memoryview(body)
        received = 0
        deadline = time.monotonic() + deadline_s
        try:
            while received < length:
                left_s = deadline - time.monotonic()
                if left_s <= 0:
                    raise TimeoutError
                self.connection.settimeout(left_s)  # each read waits at most until the deadline
                n_bytes = self.rfile.readinto1(view[received:])
                if not n_bytes:
                    break
                received += n_bytes
        finally:
            self.connection.settimeout(self.timeout)
        del view
        return bytes(body) if received == length else bytes(body[:received])

    def log_message(self, format: str, *args: Any) -> None:
        log.info("%s %s", self.address_string(), printable(format % args))

    def log_error(self, format: str, *args: Any) -> None:
        log.warning("%s %s", self.address_string(), printable(format % args))

    def log_request(self, code: int | str = "-", size: int | str = "-") -> None:
        status = code.value if isinstance(code, HTTPStatus) else code
        line = f'"{self.requestline}" {status} {size}' + (f" ({self._error_reason})" if self._error_reason else "")
        (log.warning if status in ALWAYS_LOGGED else log.info)("%s %s", self.address_string(), printable(line))

    def send_error(self, code: int, message: str | None = None, explain: str | None = None) -> None:
        """A refusal as JSON with its reason (the standard library would send HTML)."""
        reason = message or ERROR_REASONS.get(code) or HTTPStatus(code).phrase
        if explain:
            reason = f"{reason} ({explain})"
        self._error_reason = reason
        self.close_connection = True
        self._answer(error_answer(code, reason))

    def do_GET(self) -> None:
        if self.headers.get("Content-Length", "0").strip() != "0" or "Transfer-Encoding" in self.headers:
            # Its body is never read: on a kept-alive connection it would be taken for the next request.
            self.close_connection = True
        self._answer(dispatch(self, "GET", urlsplit(self.path).path))

    def do_HEAD(self) -> None:
        self.do_GET()

    def do_POST(self) -> None:
        self.close_connection = True
        self._answer(dispatch(self, "POST", urlsplit(self.path).path))
        if not self.body_read and not self.expects_continue:
            self._drain_body()

    def _drain_body(self) -> None:
        # A client that sends its whole body before reading the answer would see its send fail
        # ("broken pipe") if the connection closed with the body unread: read it and drop it,
        # up to a bound and within the upload deadline.
        declared = self.headers.get("Content-Length", "").strip()
        if not re.fullmatch(r"[0-9]{1,15}", declared):
            return
        left = int(declared)
        settings = self.server.settings
        if left > DRAIN_LIMIT_FACTOR * settings.max_bytes:
            return
        deadline = time.monotonic() + settings.upload_deadline_s
        try:
            while left > 0 and (left_s := deadline - time.monotonic()) > 0:
                self.connection.settimeout(left_s)
                chunk = self.rfile.read1(min(left, 65_536))
                if not chunk:
                    return
                left -= len(chunk)
        except OSError:
            return

    def _answer(self, answer: Answer) -> None:
        try:
            self._write_answer(answer)
        except (BrokenPipeError, ConnectionResetError):
            # The client hung up before its answer was written: nothing to tell it, nothing to log.
            self.close_connection = True

    def _write_answer(self, answer: Answer) -> None:
        self.send_response(answer.status)
        self.send_header("Content-Type", answer.content_type)
        self.send_header("Content-Length", str(len(answer.body)))
        self.send_header("X-Content-Type-Options", "nosniff")
        self.send_header("Cache-Control", "no-store")
        for name, value in answer.headers.items():
            self.send_header(name, value)
        if self.close_connection:
            self.send_header("Connection", "close")
        self.end_headers()
        if self.command != "HEAD":
            self.wfile.write(answer.body)


def _over_capacity_answer() -> bytes:
    body = error_answer(HTTPStatus.SERVICE_UNAVAILABLE, "too many connections; try again in a moment").body
    head = (
        "HTTP/1.1 503 Service Unavailable\r\nContent-Type: application/json\r\nConnection: close\r\n"
        f"Content-Length: {len(body)}\r\n\r\n"
    )
    return head.encode() + body


#: Sent, without waiting, to a connection over the limits before it is closed.
_OVER_CAPACITY = _over_capacity_answer()


class LeaderboardHTTPServer(ThreadingHTTPServer):
    """A threading server that carries the :class:`ServerSettings` and the :class:`RankingCache`.

    It caps open connections (in all and per client address), closes connections whose request
    line and headers do not arrive within ``header_timeout_s``, and pauses accepting while the
    process has no file descriptor left.
    """

    daemon_threads = True
    request_queue_size = 128  # 50 readers connecting at once must not overflow the listen backlog

    def __init__(self, address: tuple[str, int], settings: ServerSettings) -> None:
        self.settings = settings
        self.ranking = RankingCache(settings.store)
        self._lock = threading.Lock()
        self._connections: dict[socket.socket, str] = {}
        self._per_address: Counter[str] = Counter()
        self._heads: dict[Handler, float] = {}  # handler -> deadline of its request line and headers
        self._refused_connections = 0
        self._failed_accepts = 0
        self._next_report = time.monotonic() + REPORT_EVERY_S
        super().__init__(address, Handler)

    def open_connections(self) -> int:
        """Connections being served now."""
        with self._lock:
            return len(self._connections)

    # Connections ---------------------------------------------------------------------------

    def get_request(self) -> tuple[socket.socket, Any]:
        try:
            return super().get_request()
        except OSError as exc:
            if exc.errno in (errno.EMFILE, errno.ENFILE, errno.ENOBUFS, errno.ENOMEM):
                # The pending connection stays in the backlog and the socket stays readable:
                # without a pause the loop would retry at full speed.
                with self._lock:
                    self._failed_accepts += 1
                time.sleep(ACCEPT_BACKOFF_S)
            raise

    def verify_request(self, request: Any, client_address: Any) -> bool:
        address = client_address[0]
        with self._lock:
            admitted = (
                len(self._connections) < self.settings.max_connections
                and self._per_address[address] < self.settings.max_connections_per_address
            )
            if admitted:
                self._connections[request] = address
                self._per_address[address] += 1
            else:
                self._refused_connections += 1
        if not admitted:
            try:
                request.setblocking(False)
                request.send(_OVER_CAPACITY)
            except OSError:
                pass
        return admitted

    def close_request(self, request: Any) -> None:
        super().close_request(request)
        with self._lock:
            address = self._connections.pop(request, None)
            if address is not None:
                self._per_address[address] -= 1
                if not self._per_address[address]:
                    del self._per_address[address]

    # Request heads -------------------------------------------------------------------------

    def watch_head(self, handler: Handler) -> None:
        with self._lock:
            self._heads[handler] = time.monotonic() + self.settings.header_timeout_s

    def head_done(self, handler: Handler) -> bool:
        """Stop watching the handler's request head; whether its deadline had passed."""
        with self._lock:
            self._heads.pop(handler, None)
            return handler.head_expired

    def service_actions(self) -> None:
        """Between accepts (at least twice a second): end request heads past their deadline, report refusals."""
        super().service_actions()
        now = time.monotonic()
        with self._lock:
            expired = [handler for handler, deadline in self._heads.items() if deadline <= now]
            for handler in expired:
                del self._heads[handler]
                handler.head_expired = True
                try:
                    # The handler's reads now end; it can still write its 408.
                    handler.connection.shutdown(socket.SHUT_RD)
                except OSError:
                    pass
            if now < self._next_report:
                return
            refused, failed = self._refused_connections, self._failed_accepts
            self._refused_connections = self._failed_accepts = 0
            self._next_report = now + REPORT_EVERY_S
        if refused:
            log.warning("refused %d connections over the limits (%d in all, %d per address)", refused,
                        self.settings.max_connections, self.settings.max_connections_per_address)
        if failed:
            log.warning("%d connections could not be accepted: no file descriptor left", failed)
