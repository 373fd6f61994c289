"""The HTTP server: its settings and state, and the request handler that answers from the route table.

What each URL answers is in :mod:`zendar_leaderboard.routes`; this module is the standard library's
``http.server`` around it. The server object carries the :class:`ServerSettings` and the
:class:`RankingCache`; nothing is kept in module globals.
"""

from __future__ import annotations

import logging
import secrets
import threading
from dataclasses import dataclass
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any
from urllib.parse import parse_qs, urlsplit

from zendar_dataset.eval.protocol import ALL_BAND
from zendar_leaderboard import ranking
from zendar_leaderboard.ground_truth import TestSplit
from zendar_leaderboard.pages import ranking_page
from zendar_leaderboard.routes import UPLOAD_PATH, Answer, admit_upload, dispatch
from zendar_leaderboard.scheduler import ScoringService
from zendar_leaderboard.scoring import BANDS
from zendar_leaderboard.store import Store

log = logging.getLogger("zendar_leaderboard")


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
    """One request, answered by :func:`zendar_leaderboard.routes.dispatch`."""

    server: LeaderboardHTTPServer
    server_version = "zendar-leaderboard"
    sys_version = ""
    timeout = 60  # seconds a client may stay silent (a stalled upload cannot hold a thread for ever)

    @property
    def band(self) -> str:
        """The band the ranking is sorted by: ``?sort=BAND``, ``all`` unless a known band."""
        sort = parse_qs(urlsplit(self.path).query).get("sort", [ALL_BAND])[0]
        return sort if sort in BANDS else ALL_BAND

    def log_message(self, format: str, *args: Any) -> None:
        log.info("%s %s", self.address_string(), format % args)

    def do_GET(self) -> None:
        self._answer(dispatch(self, "GET", urlsplit(self.path).path))

    def do_HEAD(self) -> None:
        self.do_GET()

    def do_POST(self) -> None:
        self.close_connection = True  # the body of a refused upload is never read
        self._answer(dispatch(self, "POST", urlsplit(self.path).path))

    def handle_expect_100(self) -> bool:
        # A client that waits for "100 Continue" learns of a refusal before sending anything.
        if self.command == "POST" and urlsplit(self.path).path == UPLOAD_PATH:
            admitted = admit_upload(self)
            if isinstance(admitted, Answer):
                self._answer(admitted)
                self.close_connection = True
                return False
        return super().handle_expect_100()

    def _answer(self, answer: Answer) -> None:
        self.send_response(answer.status)
        self.send_header("Content-Type", answer.content_type)
        self.send_header("Content-Length", str(len(answer.body)))
        self.send_header("X-Content-Type-Options", "nosniff")
        self.send_header("Cache-Control", "no-store")
        for name, value in answer.headers.items():
            self.send_header(name, value)
        self.end_headers()
        if self.command != "HEAD":
            self.wfile.write(answer.body)


class LeaderboardHTTPServer(ThreadingHTTPServer):
    """A threading server that carries the :class:`ServerSettings` and the :class:`RankingCache`."""

    daemon_threads = True
    request_queue_size = 128  # 50 readers connecting at once must not overflow the listen backlog

    def __init__(self, address: tuple[str, int], settings: ServerSettings) -> None:
        self.settings = settings
        self.ranking = RankingCache(settings.store)
        super().__init__(address, Handler)
