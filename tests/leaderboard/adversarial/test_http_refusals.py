"""Refusals reach the client with their reason: ``Expect: 100-continue`` is answered, a client that
sends its body first still reads the refusal, ``submit`` prints the server's reason for 401, 413 and
429 on a large file, and the parser's own refusals (414, 431) are JSON."""

from __future__ import annotations

import json

import pytest

from tests.leaderboard.adversarial.rawhttp import (
    connect,
    json_body,
    read_answer,
    read_head,
    read_until_closed,
    status_of,
    upload_head,
)
from tests.leaderboard.conftest import InProcessServer, ground_truth, submission
from tests.leaderboard.helpers import post_submission, request
from zendar_leaderboard.cli import main

LARGE_BYTES = 12_000_000


@pytest.fixture(scope="module")
def roomy_board(tmp_path_factory):
    """Uploads up to 20 MB, one submission per team."""
    server = InProcessServer(tmp_path_factory.mktemp("roomy"), ground_truth(), quota=1, max_bytes=20_000_000)
    yield server
    server.stop()


@pytest.fixture(scope="module")
def large_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("large") / "large.json"
    path.write_bytes(b"{" + b" " * (LARGE_BYTES - 2) + b"}")
    return path


def test_100_continue_comes_only_once_the_headers_pass(board):
    body = json.dumps(submission(ground_truth())).encode()
    with connect(board.url) as sock:
        sock.sendall(upload_head("wrong-token", len(body), expect_continue=True))
        answer = read_answer(sock)
    assert status_of(answer) == 401 and b"100 Continue" not in answer
    with connect(board.url) as sock:
        sock.sendall(upload_head(board.store.add_team("continue"), len(body), expect_continue=True))
        assert read_head(sock).startswith(b"HTTP/1.1 100 Continue\r\n")
        sock.sendall(body)
        answer = read_answer(sock)
    assert status_of(answer) == 202, answer


def test_a_client_that_sends_its_body_first_reads_the_refusal(roomy_board, large_file):
    status, answer = request(f"{roomy_board.url}/api/submissions", token="wrong-token", body=large_file.read_bytes())
    assert status == 401 and "token" in answer["error"]


def _submit(url: str, token: str, path, tmp_path, capsys) -> tuple[int, str]:
    token_file = tmp_path / "token"
    token_file.write_text(token)
    status = main(["submit", str(path), "--server", url, "--token-file", str(token_file), "--no-wait"])
    return status, capsys.readouterr().err


def test_submit_prints_the_servers_reason_for_a_wrong_token(roomy_board, large_file, tmp_path, capsys):
    status, err = _submit(roomy_board.url, "wrong-token", large_file, tmp_path, capsys)
    assert status == 2 and "(401)" in err and "missing or wrong token" in err
    assert "Broken pipe" not in err


def test_submit_prints_the_servers_reason_for_a_used_quota(roomy_board, large_file, tmp_path, capsys):
    token = roomy_board.store.add_team("quota-one")
    assert post_submission(roomy_board.url, token, submission(ground_truth()))[0] == 202
    status, err = _submit(roomy_board.url, token, large_file, tmp_path, capsys)
    assert status == 2 and "(429)" in err and "has used its 1 submissions" in err


def test_submit_prints_the_servers_reason_for_a_file_over_the_limit(board, large_file, tmp_path, capsys):
    status, err = _submit(board.url, board.store.add_team("too-large"), large_file, tmp_path, capsys)
    assert status == 2 and "(413)" in err and "over the limit of 5,000,000 bytes" in err


@pytest.mark.parametrize(
    ("head", "status", "reason"),
    [
        (b"GET /" + b"a" * 70_000 + b" HTTP/1.1\r\n\r\n", 414, "request line is longer"),
        (b"GET / HTTP/1.1\r\n" + b"".join(b"X-%d: 1\r\n" % k for k in range(120)) + b"\r\n", 431, "too many headers"),
        (b"GET / HTTP/1.1\r\nX-Long: " + b"a" * 70_000 + b"\r\n\r\n", 431, "header line"),
    ],
    ids=["414", "431-count", "431-length"],
)
def test_the_parsers_refusals_are_json_with_a_reason(board, head, status, reason):
    with connect(board.url) as sock:
        sock.sendall(head)
        answer = read_answer(sock)
    assert status_of(answer) == status
    assert b"Content-Type: application/json" in answer
    assert reason.lower() in json_body(answer)["error"].lower()


def test_a_request_line_that_is_not_http_1_gets_the_reason_as_json(board):
    # Not HTTP/1.x: answered as HTTP/0.9 answers, the body alone.
    with connect(board.url) as sock:
        sock.sendall(b"NONSENSE\r\n\r\n")
        answer = read_until_closed(sock)
    assert json.loads(answer) == {"error": "Bad request syntax ('NONSENSE')"}


def test_a_body_sent_with_a_get_is_never_taken_for_a_request(board):
    smuggled = b"GET /api/leaderboard HTTP/1.1\r\nHost: x\r\n\r\n"
    with connect(board.url) as sock:
        sock.sendall(b"GET /submit HTTP/1.1\r\nHost: x\r\nContent-Length: %d\r\n\r\n" % len(smuggled) + smuggled)
        answers = read_until_closed(sock)
    assert answers.count(b"HTTP/1.1 200") == 1 and b"Connection: close" in answers


def test_a_missing_frame_is_explained_without_options_the_server_lacks(board):
    document = submission(ground_truth())
    del document["results"]["scene-00/900000000"]
    status, answer = post_submission(board.url, board.store.add_team("missing-frame"), document)
    assert status == 422
    (problem,) = [p for p in answer["problems"] if "missing from predictions" in p]
    assert "--partial" not in problem and "every frame of the test split is required" in problem
