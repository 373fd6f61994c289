"""Slow bodies: an upload's body has a deadline in all; its slot is taken only once its headers pass
and given back at the deadline; slow bodies never hold the checking slots, so two of them do not
stop other uploads; and a team has one upload in progress at a time."""

from __future__ import annotations

import select
import threading
import time

import pytest

from tests.leaderboard.adversarial.rawhttp import connect, json_body, read_answer, status_of, upload_head
from tests.leaderboard.conftest import InProcessServer, ground_truth, submission
from tests.leaderboard.helpers import post_submission
from zendar_leaderboard.server import ServerSettings, default_upload_deadline_s

DEADLINE_S = 1.0
TRICKLE_EVERY_S = 0.2


@pytest.fixture(scope="module")
def slow_board(tmp_path_factory):
    server = InProcessServer(tmp_path_factory.mktemp("slow"), ground_truth(), quota=20)
    server.http.settings.upload_deadline_s = DEADLINE_S
    yield server
    server.stop()


class Trickler(threading.Thread):
    """An upload that declares 100,000 bytes and sends one every TRICKLE_EVERY_S, then reads the answer
    (or gives up when stopped)."""

    def __init__(self, url: str, token: str) -> None:
        super().__init__(daemon=True)
        self.sock = connect(url)
        self.sock.sendall(upload_head(token, 100_000))
        self.answer = b""
        self.stopped = threading.Event()

    def run(self) -> None:
        try:
            for _ in range(int(60 / TRICKLE_EVERY_S)):
                if self.stopped.is_set():
                    return
                if select.select([self.sock], [], [], 0)[0]:  # the server has answered
                    break
                self.sock.sendall(b" ")
                time.sleep(TRICKLE_EVERY_S)
            self.answer = read_answer(self.sock)
        finally:
            self.sock.close()


def test_two_slow_bodies_do_not_stop_other_uploads(slow_board):
    slow_board.http.settings.upload_deadline_s = 60.0
    attackers = [Trickler(slow_board.url, slow_board.store.add_team(f"slow-{k}")) for k in range(2)]
    try:
        for attacker in attackers:
            attacker.start()
        time.sleep(2 * TRICKLE_EVERY_S)  # both are sending their bodies now
        for k in range(3):
            status, answer = post_submission(slow_board.url, slow_board.store.add_team(f"honest-{k}"),
                                             submission(ground_truth()))
            assert status == 202, answer
        assert all(attacker.is_alive() and not attacker.answer for attacker in attackers)
    finally:
        slow_board.http.settings.upload_deadline_s = DEADLINE_S
        for attacker in attackers:
            attacker.stopped.set()
            attacker.join(timeout=60)


def test_a_slow_body_is_refused_at_the_deadline_and_gives_its_slot_back(slow_board):
    settings = slow_board.http.settings
    receive_slots, settings.receive_slots = settings.receive_slots, threading.BoundedSemaphore(1)
    try:
        attacker = Trickler(slow_board.url, slow_board.store.add_team("slow-alone"))
        attacker.start()
        time.sleep(2 * TRICKLE_EVERY_S)  # it holds the only receiving slot now
        status, answer = post_submission(slow_board.url, slow_board.store.add_team("after-slow"), submission(ground_truth()))
        assert status == 202, answer
        attacker.join(timeout=60)
        assert status_of(attacker.answer) == 408
        assert "did not arrive within the limit of 1 s" in json_body(attacker.answer)["error"]
    finally:
        settings.receive_slots = receive_slots


def test_a_team_has_one_upload_in_progress_at_a_time(slow_board):
    token = slow_board.store.add_team("one-at-a-time")
    first = Trickler(slow_board.url, token)
    first.start()
    time.sleep(2 * TRICKLE_EVERY_S)
    status, answer = post_submission(slow_board.url, token, submission(ground_truth()))
    assert status == 429 and "in progress" in answer["error"]
    first.join(timeout=60)
    assert status_of(first.answer) == 408
    status, answer = post_submission(slow_board.url, token, submission(ground_truth()))
    assert status == 202, answer


def test_an_upload_refused_from_its_headers_holds_no_slot(slow_board):
    slow_board.http.settings.upload_deadline_s = 60.0
    try:
        # Wrong tokens trickling bodies: refused at once, so they never hold the two slots.
        refused = [Trickler(slow_board.url, "wrong-token") for _ in range(3)]
        for sock in refused:
            sock.start()
        for sock in refused:
            sock.join(timeout=60)
            assert status_of(sock.answer) == 401
        status, answer = post_submission(slow_board.url, slow_board.store.add_team("after-refusals"),
                                         submission(ground_truth()))
        assert status == 202, answer
    finally:
        slow_board.http.settings.upload_deadline_s = DEADLINE_S


def test_the_default_deadline_allows_the_largest_upload_at_250_kb_per_s(slow_board):
    settings = ServerSettings(slow_board.store, slow_board.test_split, None, quota=3, max_bytes=25_000_000)
    assert settings.upload_deadline_s == default_upload_deadline_s(25_000_000) == 10.0 + 100.0
