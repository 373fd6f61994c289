"""What each URL answers: the route table (method + path pattern -> view) and the views.

Routes (docs/leaderboard.md): ``POST /api/submissions``, ``GET /api/submissions/ID``,
``GET /api/leaderboard``, ``GET /``, ``GET /entry/ID``, ``GET /submit``, ``GET /leaderboard.json``,
``GET /leaderboard.csv``; ``HEAD`` answers as ``GET`` without the body, anything else is 404.

A view takes the request (the server's handler: headers, body, ``band``, and ``server`` with its
settings and ranking cache) and the path pattern's groups, and returns an :class:`Answer`.

An upload is refused before its body is read when the token is missing or wrong (401), the declared
``Content-Length`` is missing (411) or over the limit (413), the round is closed (403), the team's
quota is used or it has an upload in progress already (429), or no receiving slot frees within
UPLOAD_SLOT_WAIT_S (503). Otherwise it takes a receiving slot, its body is read within the upload
deadline (408 when it is slower), then it takes a checking slot and is checked whole (422 with the
first problems and how many more), recorded and queued (202). Slow bodies hold receiving slots,
never checking slots. Nothing in a request is ever used as a file name: the server reads
only the labels and database it was started with.
"""

from __future__ import annotations

import re
import secrets
from collections.abc import Callable
from dataclasses import dataclass, field
from http import HTTPStatus
from typing import TYPE_CHECKING, Any

import orjson

from zendar_leaderboard import ranking
from zendar_leaderboard.pages import entry_page, submit_page
from zendar_leaderboard.scoring import BANDS
from zendar_leaderboard.store import QuotaExceeded, RoundClosed, StoreUnavailable, Team
from zendar_leaderboard.submission import check_submission

if TYPE_CHECKING:
    from zendar_leaderboard.server import Handler

UPLOAD_PATH = "/api/submissions"
# ASCII digits only: str.isdigit() also accepts '²', which int() then refuses.
_CONTENT_LENGTH = re.compile(r"[0-9]{1,15}")
#: How long an upload whose headers passed waits for a receiving or a checking slot before the
#: server answers 503.
UPLOAD_SLOT_WAIT_S = 30.0
#: At most this many problems are listed in a 422 answer, each at most PROBLEM_CHARS long; the
#: rest are counted, never built.
MAX_PROBLEMS = 1000
PROBLEM_CHARS = 300


# Answers -------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Answer:
    """One HTTP answer (the server adds Content-Length, nosniff and no-store to every answer)."""

    status: int
    body: bytes
    content_type: str
    headers: dict[str, str] = field(default_factory=dict)


def json_answer(status: int, document: Any, headers: dict[str, str] | None = None) -> Answer:
    return Answer(status, orjson.dumps(document), "application/json", headers or {})


def error_answer(status: int, message: str, **extra: Any) -> Answer:
    """``{"error": message, **extra}``; a 401 says which scheme it wants."""
    headers = {"WWW-Authenticate": "Bearer"} if status == HTTPStatus.UNAUTHORIZED else None
    return json_answer(status, {"error": message, **extra}, headers)


def html_answer(render: Callable[[str], str]) -> Answer:
    """A page rendered with a fresh nonce, under a Content-Security-Policy that runs only what carries it."""
    nonce = secrets.token_urlsafe(16)
    csp = (
        f"default-src 'none'; script-src 'nonce-{nonce}'; style-src 'nonce-{nonce}'; "
        "connect-src 'self'; img-src 'self' data:; form-action 'self'; base-uri 'none'; frame-ancestors 'none'"
    )
    return Answer(HTTPStatus.OK, render(nonce).encode(), "text/html; charset=utf-8", {"Content-Security-Policy": csp})


NOT_FOUND = error_answer(HTTPStatus.NOT_FOUND, "no such resource")


# Teams, quotas and limits --------------------------------------------------------------------


def _team(request: Handler) -> Team | None:
    match = re.fullmatch(r"Bearer\s+(\S{1,200})", request.headers.get("Authorization", "").strip())
    return None if match is None else request.server.settings.store.team_for_token(match.group(1))


def _unauthorized() -> Answer:
    return error_answer(HTTPStatus.UNAUTHORIZED, "missing or wrong token (send 'Authorization: Bearer TOKEN')")


def _quota_used(request: Handler, team: Team) -> Answer:
    return error_answer(
        HTTPStatus.TOO_MANY_REQUESTS,
        f"team {team.name!r} has used its {request.server.settings.quota} submissions of the last 30 days",
    )


def admit_upload(request: Handler) -> tuple[Team, int] | Answer:
    """The checks that need no body: the team and the declared length, or the refusal."""
    settings = request.server.settings
    team = _team(request)
    if team is None:
        return _unauthorized()
    declared = request.headers.get("Content-Length")
    if declared is None:
        return error_answer(HTTPStatus.LENGTH_REQUIRED, "a Content-Length header is required")
    if not _CONTENT_LENGTH.fullmatch(declared.strip()):
        return error_answer(HTTPStatus.BAD_REQUEST, "Content-Length must be a number of bytes")
    length = int(declared)
    if length > settings.max_bytes:
        return error_answer(
            HTTPStatus.REQUEST_ENTITY_TOO_LARGE,
            f"the submission is {length:,} bytes, over the limit of {settings.max_bytes:,} bytes",
        )
    if settings.store.round_closed():
        return error_answer(HTTPStatus.FORBIDDEN, "the round is closed: submissions are not taken")
    if settings.store.submissions_in_window(team.id) >= settings.quota:
        return _quota_used(request, team)
    return team, length


def _shape_problems(problems: list[str], not_listed: int) -> list[str]:
    shown = [p if len(p) <= PROBLEM_CHARS else p[: PROBLEM_CHARS - 3] + "..." for p in problems[:MAX_PROBLEMS]]
    not_listed += max(0, len(problems) - MAX_PROBLEMS)
    if not_listed:
        shown.append(f"... and {not_listed:,} more problem{'s' if not_listed != 1 else ''}")
    return shown


# Views ---------------------------------------------------------------------------------------


def upload(request: Handler) -> Answer:
    """``POST /api/submissions``: check, record and queue a submission."""
    admitted = admit_upload(request)
    if isinstance(admitted, Answer):
        return admitted
    team, length = admitted
    settings = request.server.settings
    if not settings.begin_team_upload(team.id):
        return error_answer(
            HTTPStatus.TOO_MANY_REQUESTS,
            f"team {team.name!r} has {settings.uploads_per_team} upload(s) in progress already; "
            "send the next one once it is answered",
        )
    try:
        return _receive(request, team, length)
    finally:
        settings.end_team_upload(team.id)


def _receive(request: Handler, team: Team, length: int) -> Answer:
    """Read, check, record and queue an upload whose headers passed."""
    settings = request.server.settings
    busy = error_answer(HTTPStatus.SERVICE_UNAVAILABLE, "the server is busy with other uploads; try again shortly")
    # Slots are taken once the headers pass: bodies in memory at once are bounded by the receiving
    # slots, parsed uploads by the checking slots, and the deadline bounds how long a slow body
    # holds its receiving slot. A slow body never holds a checking slot.
    if not settings.receive_slots.acquire(timeout=UPLOAD_SLOT_WAIT_S):
        return busy
    try:
        request.send_continue()
        try:
            body = request.read_body(length, settings.upload_deadline_s)
        except TimeoutError:
            return error_answer(
                HTTPStatus.REQUEST_TIMEOUT,
                f"the upload's {length:,} bytes did not arrive within the limit of {settings.upload_deadline_s:g} s; "
                "nothing was recorded",
            )
        if len(body) != length:
            return error_answer(HTTPStatus.BAD_REQUEST, f"the body ended after {len(body):,} of {length:,} bytes")
        if not settings.check_slots.acquire(timeout=UPLOAD_SLOT_WAIT_S):
            return busy
        try:
            checked = check_submission(body, settings.gt_frame_ids, max_problems=MAX_PROBLEMS)
            checked.document = None  # only the bytes are kept
        finally:
            settings.check_slots.release()
    finally:
        settings.receive_slots.release()
    if not checked.ok:
        n = checked.problem_count
        return error_answer(
            HTTPStatus.UNPROCESSABLE_ENTITY,
            f"{n:,} problem{'s' if n != 1 else ''} in the submission; nothing was queued",
            problems=_shape_problems(checked.problems, checked.problems_not_listed),
        )
    try:
        submission_id = settings.store.add_submission(team, body, checked.sha256, checked.meta, settings.quota)
    except QuotaExceeded:
        return _quota_used(request, team)
    except RoundClosed as exc:
        return error_answer(HTTPStatus.FORBIDDEN, str(exc))
    except StoreUnavailable as exc:  # a held lock or a full disk: nothing recorded, the quota untouched
        return error_answer(HTTPStatus.SERVICE_UNAVAILABLE, f"{exc}; nothing was recorded, try again later")
    if settings.scoring is not None:
        settings.scoring.wake()
    return json_answer(HTTPStatus.ACCEPTED, {"id": submission_id, "status": "queued"})


def submission_status(request: Handler, submission_id: str) -> Answer:
    """``GET /api/submissions/ID``: a team's own submission, its queue position or shown score."""
    team = _team(request)
    if team is None:
        return _unauthorized()
    store = request.server.settings.store
    submission = store.submission(int(submission_id))
    if submission is None or submission.team_id != team.id:  # another team's ids are not confirmed
        return error_answer(HTTPStatus.NOT_FOUND, f"no submission {int(submission_id)} of team {team.name!r}")
    answer: dict[str, Any] = {"id": submission.id, "status": submission.status}
    if submission.status == "queued":
        answer["position"] = store.queue_position(submission.id)
    if submission.status == "scored":
        part_name, part = ranking.shown_score(store.score(submission.id), store.round_closed())
        answer["ap"] = part.get("ap", {band: None for band in BANDS})
        if part.get("ci"):
            answer["ci"] = part["ci"]
        answer["part"] = part_name
    if submission.status == "failed":
        answer["error"] = submission.error
    answer["submitted_at"] = ranking.iso_utc(submission.submitted_at)
    answer["sha256"] = submission.sha256
    return json_answer(HTTPStatus.OK, answer)


def leaderboard_json(request: Handler) -> Answer:
    """``GET /api/leaderboard`` and ``GET /leaderboard.json``."""
    return json_answer(HTTPStatus.OK, request.server.ranking.board(request.band))


def leaderboard_csv(request: Handler) -> Answer:
    """``GET /leaderboard.csv``."""
    text = ranking.to_csv(request.server.ranking.board(request.band))
    return Answer(HTTPStatus.OK, text.encode(), "text/csv; charset=utf-8")


def ranking_html(request: Handler) -> Answer:
    """``GET /`` (and ``/index.html``): the ranking page."""
    band = request.band
    return html_answer(lambda nonce: request.server.ranking.page(band, nonce))


def entry_html(request: Handler, submission_id: str) -> Answer:
    """``GET /entry/ID``: one entry on the leaderboard."""
    found = ranking.entry_parts(request.server.settings.store, int(submission_id))
    if found is None:
        return error_answer(HTTPStatus.NOT_FOUND, f"no entry {int(submission_id)} on the leaderboard")
    entry, parts = found
    return html_answer(lambda nonce: entry_page(entry, parts, static=False, nonce=nonce))


def submit_html(request: Handler) -> Answer:
    """``GET /submit``: the upload form."""
    settings = request.server.settings
    return html_answer(lambda nonce: submit_page(quota=settings.quota, max_bytes=settings.max_bytes, nonce=nonce))


# The table -----------------------------------------------------------------------------------


@dataclass(frozen=True)
class Route:
    """``method`` requests whose whole path matches ``pattern`` go to ``view(request, *groups)``."""

    method: str
    pattern: re.Pattern[str]
    view: Callable[..., Answer]


def _route(method: str, pattern: str, view: Callable[..., Answer]) -> Route:
    return Route(method, re.compile(pattern), view)


ROUTES: tuple[Route, ...] = (
    _route("POST", re.escape(UPLOAD_PATH), upload),
    _route("GET", r"/api/submissions/(\d{1,18})", submission_status),
    _route("GET", r"/api/leaderboard", leaderboard_json),
    _route("GET", r"/leaderboard\.json", leaderboard_json),
    _route("GET", r"/leaderboard\.csv", leaderboard_csv),
    _route("GET", r"/|/index\.html", ranking_html),
    _route("GET", r"/submit", submit_html),
    _route("GET", r"/entry/(\d{1,18})", entry_html),
)


def dispatch(request: Handler, method: str, path: str) -> Answer:
    """The answer of the first route for ``method`` whose pattern matches all of ``path`` (404 when none)."""
    for route in ROUTES:
        if route.method == method and (match := route.pattern.fullmatch(path)) is not None:
            return route.view(request, *match.groups())
    return NOT_FOUND
