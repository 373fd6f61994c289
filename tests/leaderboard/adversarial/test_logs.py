"""The log: control characters from requests are escaped, and requests the server could not parse
are logged without --verbose, one line each."""

from __future__ import annotations

import logging
import re

import pytest

from tests.leaderboard.adversarial.rawhttp import connect, read_answer, read_until_closed, status_of

CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f]")


def test_control_characters_in_request_lines_are_escaped(board, caplog):
    caplog.set_level(logging.INFO, logger="zendar_leaderboard")  # as with --verbose
    with connect(board.url) as sock:
        sock.sendall(b"GET /\x1b]0;owned\x07\x1b[2J\x9b HTTP/1.1\r\nConnection: close\r\n\r\n")
        assert status_of(read_answer(sock)) == 404
    lines = [record.getMessage() for record in caplog.records if "owned" in record.getMessage()]
    assert lines and not any(CONTROL.search(line) for line in lines)
    assert "\\x1b]0;owned\\x07\\x1b[2J" in lines[0]


@pytest.mark.parametrize(
    ("head", "status"),
    [
        (b"GET /\x1b[31m HTTP/1.x\r\n\r\n", 400),
        (b"GET / HTTP/9.9\r\n\r\n", 505),
        (b"GET /" + b"a" * 70_000 + b" HTTP/1.1\r\n\r\n", 414),
        (b"GET / HTTP/1.1\r\n" + b"".join(b"X-%d: 1\r\n" % k for k in range(120)) + b"\r\n", 431),
    ],
    ids=["400", "505", "414", "431"],
)
def test_unparsable_requests_are_logged_without_verbose(board, caplog, head, status):
    caplog.set_level(logging.WARNING, logger="zendar_leaderboard")  # without --verbose
    with connect(board.url) as sock:
        sock.sendall(head)
        read_until_closed(sock)
    lines = [record.getMessage() for record in caplog.records
             if record.name == "zendar_leaderboard" and record.levelno >= logging.WARNING]
    assert len(lines) == 1 and f" {status} " in lines[0]
    assert not CONTROL.search(lines[0])
