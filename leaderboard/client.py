"""``zendar-leaderboard submit``: upload a submission, wait for its score, print the table.

The upload is sent with ``Expect: 100-continue``: the body follows only once the server has
accepted the headers (token, size, quota), so a refusal arrives whole with its reason instead of
as a connection broken in the middle of the body.
"""

from __future__ import annotations

import http.client
import json
import select
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from zendar_dataset.errors import ZendarError
from zendar_leaderboard.scoring import BANDS, format_ap_percent


#: How long the upload waits for "100 Continue" or a refusal before sending the body anyway (a
#: server that ignores the header; the leaderboard answers within its 30 s wait for a checking slot).
CONTINUE_WAIT_S = 40.0


class ServerUnreachable(OSError):
    """The server could not be reached (an environment failure, not the user's file)."""


def check_server_url(url: str) -> str:
    """``url`` when it can name a leaderboard: ``http(s)://HOST[:PORT][/PATH]``.

    Raises
    ------
    ValueError
        Saying what is wrong: another scheme or none, no host, a port out of 1-65535, a query,
        fragment or user name (the API paths are appended to it), a space or a control character.
    """
    if any(ord(character) <= 0x20 or ord(character) == 0x7F for character in url):
        raise ValueError("it holds a space or a control character")
    parts = urlsplit(url)  # ValueError: "Invalid IPv6 URL"
    if parts.scheme not in ("http", "https") or not parts.hostname:
        raise ValueError("expected http://HOST[:PORT] or https://HOST[:PORT]")
    try:
        connectable = parts.port != 0
    except ValueError:  # not a number, or above 65535
        connectable = False
    if not connectable:
        raise ValueError("the port must be a number from 1 to 65535")
    if "?" in url or "#" in url or "@" in parts.netloc:
        raise ValueError("a query, fragment or user name cannot be part of it")
    return url


def _answer_document(raw: bytes, reason: str) -> Any:
    try:
        return json.loads(raw)
    except ValueError:
        return {"error": reason or "no reason given"}


def _post(url: str, token: str, body: bytes, timeout_s: float) -> tuple[int, Any]:
    """POST ``body`` with ``Expect: 100-continue``; (status, parsed answer)."""
    parts = urlsplit(url)
    connection_type = http.client.HTTPSConnection if parts.scheme == "https" else http.client.HTTPConnection
    connection = connection_type(parts.hostname, parts.port, timeout=timeout_s)
    try:
        connection.putrequest("POST", parts.path or "/")
        connection.putheader("Authorization", f"Bearer {token}")
        connection.putheader("Content-Type", "application/json")
        connection.putheader("Content-Length", str(len(body)))
        connection.putheader("Expect", "100-continue")
        connection.endheaders()
        early = _early_answer(connection.sock)
        if early is not None:
            return early
        try:
            connection.send(body)
        except (BrokenPipeError, ConnectionResetError):
            pass  # the server answered and closed while the body was on its way: its answer says why
        response = connection.getresponse()
        return response.status, _answer_document(response.read(), response.reason)
    except (OSError, http.client.HTTPException) as exc:
        raise ServerUnreachable(f"cannot reach {url}: {exc}") from None
    finally:
        connection.close()


def _early_answer(sock: Any) -> tuple[int, Any] | None:
    """The server's final answer when it came before the body (a refusal from the headers); None
    when it asked for the body ("100 Continue", read here) or said nothing within CONTINUE_WAIT_S."""
    pending = getattr(sock, "pending", lambda: 0)()  # TLS may hold decrypted bytes that select misses
    if not pending and not select.select([sock], [], [], CONTINUE_WAIT_S)[0]:
        return None
    # Unbuffered: not a byte past the interim answer is taken from the socket.
    stream = sock.makefile("rb", buffering=0)
    try:
        words = stream.readline(65537).split(None, 2)
        headers = http.client.parse_headers(stream)
        if len(words) < 2 or not words[1].isdigit():
            raise http.client.BadStatusLine(repr(b" ".join(words))[:80])
        status = int(words[1])
        if status == 100:
            return None
        left = int(headers.get("Content-Length") or 0)
        chunks = []
        while left > 0 and (chunk := stream.read(left)):
            chunks.append(chunk)
            left -= len(chunk)
        reason = words[2].decode(errors="replace").strip() if len(words) > 2 else ""
        return status, _answer_document(b"".join(chunks), reason)
    finally:
        stream.close()


def _request(url: str, token: str, data: bytes | None = None, timeout_s: float = 600.0) -> tuple[int, Any]:
    if data is not None:
        return _post(url, token, data, timeout_s)
    request = urllib.request.Request(url, method="GET")
    request.add_header("Authorization", f"Bearer {token}")
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
