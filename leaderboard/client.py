"""``zendar-leaderboard submit``: upload a submission, wait for its score, print the table."""

from __future__ import annotations

import json
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path
from typing import Any

from zendar_dataset.errors import ZendarError
from zendar_leaderboard.scoring import BANDS, format_ap_percent


class ServerUnreachable(OSError):
    """The server could not be reached (an environment failure, not the user's file)."""


def _request(url: str, token: str, data: bytes | None = None, timeout_s: float = 600.0) -> tuple[int, Any]:
    request = urllib.request.Request(url, data=data, method="POST" if data is not None else "GET")
    request.add_header("Authorization", f"Bearer {token}")
    if data is not None:
        request.add_header("Content-Type", "application/json")
    try:
        with urllib.request.urlopen(request, timeout=timeout_s) as response:
            return response.status, json.loads(response.read())
    except urllib.error.HTTPError as exc:
        try:
            return exc.code, json.loads(exc.read())
        except ValueError:
            return exc.code, {"error": exc.reason}
    except (urllib.error.URLError, ConnectionError, TimeoutError) as exc:
        reason = getattr(exc, "reason", exc)
        raise ServerUnreachable(f"cannot reach {url}: {reason}") from None


def format_scores(answer: dict) -> str:
    """The score table printed by ``submit``.

    The server answers AP (and interval ends) as fractions in [0, 1] rounded to 0.001; the table
    shows them in percent with one decimal.
    """
    ci = answer.get("ci") or {}
    lines = [
        f"submission {answer['id']} scored on the {answer.get('part', 'public')} part of the test split",
        "band   AP [%]  95% CI [%]",
        "-------------------------",
    ]
    for band in BANDS:
        value = answer["ap"].get(band)
        interval = f"[{format_ap_percent(ci[band][0])}, {format_ap_percent(ci[band][1])}]" if ci.get(band) else ""
        lines.append(f"{band:<5} {format_ap_percent(value, 'n/a'):>7}  {interval}")
    return "\n".join(lines)


def submit(path: str, server: str, token: str, *, wait: bool = True, timeout_s: float = 3600.0, poll_s: float = 1.0) -> int:
    """Upload ``path`` and, with ``wait``, print a progress line until it is scored.

    Returns
    -------
    int
        0 when scored (or queued without ``wait``), 1 when scoring failed.

    Raises
    ------
    ZendarError
        When the server refuses the upload (401, 403, 413, 422, 429), with its reasons.
    ServerUnreachable
        When the server cannot be reached.
    """
    file = Path(path)
    if not file.is_file():
        raise ZendarError(f"submission file {path!r} does not exist or is not a file")
    base = server.rstrip("/")
    status, answer = _request(f"{base}/api/submissions", token, file.read_bytes())
    if status != 202:
        message = f"the server refused {path!r} ({status}): {answer.get('error', 'no reason given')}"
        raise _refusal(message, answer.get("problems") or [])
    submission_id = answer["id"]
    print(f"submission {submission_id} queued", flush=True)
    if not wait:
        return 0
    started = time.monotonic()
    while True:
        status, answer = _request(f"{base}/api/submissions/{submission_id}", token, timeout_s=60)
        if status != 200:
            raise ZendarError(f"the server did not report submission {submission_id} ({status}): {answer.get('error')}")
        elapsed = time.monotonic() - started
        if answer["status"] in ("scored", "failed"):
            if sys.stderr.isatty():
                print(file=sys.stderr)
            break
        position = f", position {answer['position']} in the queue" if answer.get("position") else ""
        end = "\r" if sys.stderr.isatty() else "\n"
        print(f"{answer['status']}{position} ({elapsed:.0f} s)", end=end, file=sys.stderr, flush=True)
        if elapsed > timeout_s:
            raise ZendarError(f"submission {submission_id} was not scored within {timeout_s:g} s; it stays queued on the server")
        time.sleep(poll_s)
    if answer["status"] == "failed":
        print(f"submission {submission_id} failed: {answer.get('error')}", file=sys.stderr)
        return 1
    print(format_scores(answer))
    return 0


def _refusal(message: str, problems: list[str]) -> ZendarError:
    error = ZendarError(message)
    error.problems = [message] + problems  # printed one per line by the command
    return error
