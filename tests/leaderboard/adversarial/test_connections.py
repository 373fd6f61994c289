"""File descriptors and connections: per-request database connections are closed, connections are
capped in all and per address, idle and slow request heads are closed, and the accept loop pauses
instead of spinning when the process has no file descriptor left."""

from __future__ import annotations

import json
import os
import resource
import select
import signal
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest

from tests.leaderboard.adversarial.rawhttp import connect, json_body, read_answer, read_until_closed, status_of
from tests.leaderboard.conftest import SERVE_TIMEOUT_S, ground_truth
from tests.leaderboard.helpers import request


def _open_fds() -> int:
    return len(os.listdir("/proc/self/fd"))


def _wait_until_idle(board) -> None:
    deadline = time.monotonic() + 30
    while board.http.open_connections() and time.monotonic() < deadline:
        time.sleep(0.05)
    assert board.http.open_connections() == 0


def test_open_files_stay_bounded_after_300_requests(board):
    request(f"{board.url}/api/leaderboard")
    _wait_until_idle(board)
    before = _open_fds()
    for _ in range(300):
        assert request(f"{board.url}/api/leaderboard")[0] == 200
    _wait_until_idle(board)
    assert _open_fds() <= before + 5


def test_connections_over_the_per_address_limit_are_refused(board):
    settings = board.http.settings
    settings.max_connections_per_address = 3
    held = [connect(board.url) for _ in range(3)]
    try:
        time.sleep(0.2)  # accepted by now
        with connect(board.url) as extra:
            answer = read_until_closed(extra)
        assert status_of(answer) == 503 and "too many connections" in json_body(answer)["error"]
    finally:
        settings.max_connections_per_address = 64
        for sock in held:
            sock.close()
    _wait_until_idle(board)
    assert request(f"{board.url}/api/leaderboard")[0] == 200


def test_connections_over_the_global_limit_are_refused(board):
    # A connection of the test before (its last request) may still be closing: counted, it would let
    # the wait below end before both held connections are, and the third would be admitted.
    _wait_until_idle(board)
    settings = board.http.settings
    settings.max_connections = 2
    held = [connect(board.url) for _ in range(2)]
    try:
        # Both held connections must be counted before the third comes (a loaded machine accepts late).
        deadline = time.monotonic() + 30
        while board.http.open_connections() < 2 and time.monotonic() < deadline:
            time.sleep(0.05)
        with connect(board.url) as extra:
            assert status_of(read_until_closed(extra)) == 503
    finally:
        settings.max_connections = 512
        for sock in held:
            sock.close()
    _wait_until_idle(board)


def test_idle_connections_and_slow_heads_are_closed_at_the_header_deadline(board):
    settings = board.http.settings
    settings.header_timeout_s = 0.5
    try:
        with connect(board.url) as idle:
            assert idle.recv(1) == b""  # closed without a word: it never asked anything
        with connect(board.url) as slow:
            slow.sendall(b"GET / HTTP/1.1\r\n")
            for k in range(300):
                if select.select([slow], [], [], 0.1)[0]:
                    break
                slow.sendall(b"X-%d: 1\r\n" % k)
            answer = read_answer(slow)
        assert status_of(answer) == 408 and "took longer than 0.5 s" in json_body(answer)["error"]
    finally:
        settings.header_timeout_s = 10.0
    _wait_until_idle(board)


def test_a_request_line_that_never_ends_gets_its_408(board, capfd):
    # The head deadline can fall before the request line is complete: the answer and its log line
    # must not need what parsing the line would have set.
    settings = board.http.settings
    settings.header_timeout_s = 0.5
    try:
        with connect(board.url) as slow:
            slow.sendall(b"GET /")
            answer = read_answer(slow)
        assert status_of(answer) == 408 and "took longer than 0.5 s" in json_body(answer)["error"]
    finally:
        settings.header_timeout_s = 10.0
    _wait_until_idle(board)
    assert "Traceback" not in capfd.readouterr().err


def _cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")  # utime + stime


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs /proc")
def test_the_accept_loop_pauses_when_no_file_descriptor_is_left(tmp_path):
    gt = tmp_path / "gt.json"
    gt.write_text(json.dumps(ground_truth()))
    log = tmp_path / "serve.log"
    hard = resource.getrlimit(resource.RLIMIT_NOFILE)[1]
    command = [sys.executable, "-m", "zendar_leaderboard.cli", "serve", "--gt", str(gt), "--db", str(tmp_path / "b.db"),
               "--port", "0", "--max-connections", "1000", "--max-connections-per-address", "1000"]
    with open(log, "wb") as out:
        server = subprocess.Popen(command, stdout=out, stderr=subprocess.STDOUT, start_new_session=True,
                                  preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_NOFILE, (64, hard)))
    clients = []
    try:
        deadline = time.monotonic() + SERVE_TIMEOUT_S
        while "serving http" not in log.read_text() and time.monotonic() < deadline:
            assert server.poll() is None, log.read_text()
            time.sleep(0.1)
        url = log.read_text().split("serving ", 1)[1].split("/ ", 1)[0]
        # More idle connections than descriptors: the server accepts until it has none left.
        clients = [connect(url) for _ in range(100)]
        time.sleep(1.0)
        before, started = _cpu_s(server.pid), time.monotonic()
        time.sleep(2.0)
        cpu_share = (_cpu_s(server.pid) - before) / (time.monotonic() - started)
        assert cpu_share < 0.1, f"the server used {cpu_share:.0%} of a CPU while out of descriptors"
        for sock in clients:
            sock.close()
        clients = []
        with urllib.request.urlopen(f"{url}/api/leaderboard", timeout=30) as response:
            assert response.status == 200
    finally:
        for sock in clients:
            sock.close()
        os.killpg(server.pid, signal.SIGKILL)
        server.wait(timeout=30)
