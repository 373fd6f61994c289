"""The HTTP API and pages of an in-process leaderboard: status codes, limits, labels kept hidden."""

from __future__ import annotations

import builtins
import io
import json
import socket
import sqlite3

import pytest

from tests.leaderboard.conftest import InProcessServer, ground_truth, submission
from tests.leaderboard.helpers import expected_ap, post_submission, request, wait_done


def raw_exchange(url: str, head: bytes, body: bytes = b"", read_timeout_s: float = 10.0) -> bytes:
    """Send ``head`` (and ``body``) on a raw socket and return whatever the server answers."""
    host, port = url.removeprefix("http://").split(":")
    with socket.create_connection((host, int(port)), timeout=read_timeout_s) as sock:
        sock.sendall(head + body)
        chunks = []
        while True:
            try:
                chunk = sock.recv(65536)
            except (ConnectionResetError, TimeoutError):
                break
            if not chunk:
                break
            chunks.append(chunk)
    return b"".join(chunks)


def test_missing_or_wrong_token_is_401(board):
    document = submission(ground_truth())
    for token in (None, "not-a-token", ""):
        status, answer = post_submission(board.url, token, document) if token is not None else request(
            f"{board.url}/api/submissions", body=json.dumps(document).encode())
        assert status == 401 and "token" in answer["error"]
    status, _ = request(f"{board.url}/api/submissions/1")
    assert status == 401
    assert board.store.submissions() == []


def test_a_body_over_the_limit_is_refused_before_it_is_read(board):
    token = board.store.add_team("big")
    # Only the headers are sent, announcing 10 GB: the answer comes without the body.
    head = (f"POST /api/submissions HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {token}\r\n"
            "Content-Type: application/json\r\nContent-Length: 10000000000\r\n\r\n").encode()
    answer = raw_exchange(board.url, head)
    assert answer.startswith(b"HTTP/1.1 413") and b"over the limit of 5,000,000 bytes" in answer
    # A client that waits for 100 Continue is told before sending anything.
    answer = raw_exchange(board.url, head.replace(b"\r\n\r\n", b"\r\nExpect: 100-continue\r\n\r\n"))
    assert answer.startswith(b"HTTP/1.1 413") and b"100 Continue" not in answer
    # No length at all: 411.
    answer = raw_exchange(board.url, head.replace(b"Content-Length: 10000000000\r\n", b""))
    assert answer.startswith(b"HTTP/1.1 411")
    # A length that str.isdigit() accepts but int() does not (latin-1 '\xb2' is a superscript two): 400.
    answer = raw_exchange(board.url, head.replace(b"Content-Length: 10000000000", b"Content-Length: \xb2"))
    assert answer.startswith(b"HTTP/1.1 400") and b"Content-Length" in answer
    assert board.store.submissions_in_window(board.store.team_for_token(token).id) == 0


def test_an_invalid_submission_is_422_with_every_problem_and_costs_nothing(board):
    gt = ground_truth()
    token = board.store.add_team("sloppy")
    document = submission(gt, method="x" * 50)
    frame_ids = list(gt["frames"])
    del document["results"][frame_ids[3]]
    document["results"][frame_ids[4]][0]["x"] = None
    status, answer = post_submission(board.url, token, document)
    assert status == 422
    assert answer["error"] == "3 problems in the submission; nothing was queued"
    assert any("'method' has 50 characters" in p for p in answer["problems"])
    assert any(f"{frame_ids[3]!r} is missing" in p for p in answer["problems"])
    assert any(f"{frame_ids[4]!r} detection 0: 'x' must be a number, got null" in p for p in answer["problems"])
    for raw in (b"[" * 100_000, b'{"meta": {}, "results": {"a/1": [{"x": 1e999}]}}', b"\xff\xfe"):
        status, answer = post_submission(board.url, token, raw)
        assert status == 422 and len(answer["problems"]) == 1
    # Three more tries are refused for content, not for quota: rejected files do not count.
    assert board.store.submissions_in_window(board.store.team_for_token(token).id) == 0


def test_a_valid_submission_is_queued_scored_and_ranked_with_the_evaluators_ap(board):
    gt = ground_truth()
    token = board.store.add_team("scorers")
    document = submission(gt, seed=5, method="ranked-one")
    status, answer = post_submission(board.url, token, document)
    assert status == 202 and answer == {"id": answer["id"], "status": "queued"}
    done = wait_done(board.url, token, answer["id"])
    assert done["status"] == "scored"
    public_ap = expected_ap(gt, document, board.test_split.public_frame_ids)
    assert done["ap"] == public_ap
    assert set(done["ci"]) == {"near", "mid", "far", "all"}  # two public scenes: intervals
    status, board_json = request(f"{board.url}/api/leaderboard")
    entry = next(e for e in board_json["entries"] if e["id"] == answer["id"])
    assert entry["method"] == "ranked-one" and entry["team"] == "scorers" and entry["ap"] == public_ap
    assert {"rank", "method", "team", "ap", "ci", "meta", "submitted_at"} <= set(entry)
    assert "contact" not in entry["meta"]
    assert entry["gt_sha256"] == board.test_split.sha256 and entry["protocol_version"] == "1.0"
    import hashlib

    assert entry["submission_sha256"] == hashlib.sha256(json.dumps(document).encode()).hexdigest()
    # Another team cannot read this submission's status.
    other = board.store.add_team("nosy")
    status, _ = request(f"{board.url}/api/submissions/{answer['id']}", token=other)
    assert status == 404


def test_a_perfect_submission_is_served_as_1_and_shown_as_100(board):
    gt = ground_truth()
    token = board.store.add_team("oracle")
    document = submission(gt, method="perfect oracle")
    document["results"] = {
        frame_id: [{"x": c["x"], "y": c["y"], "score": 1.0} for c in cars] for frame_id, cars in gt["frames"].items()
    }
    _, answer = post_submission(board.url, token, document)
    done = wait_done(board.url, token, answer["id"])
    assert done["status"] == "scored"
    # JSON carries AP as a fraction in [0, 1]: a perfect score is exactly 1.0 in every band with cars.
    assert done["ap"]["all"] == 1.0 and isinstance(done["ap"]["all"], float)
    assert all(v in (1.0, None) for v in done["ap"].values())
    assert all(interval == [1.0, 1.0] for interval in done["ci"].values() if interval)
    board_json = request(f"{board.url}/api/leaderboard")[1]
    entry = next(e for e in board_json["entries"] if e["id"] == answer["id"])
    assert entry["ap"] == done["ap"] and entry["rank"] == 1
    assert request(f"{board.url}/leaderboard.json")[1]["entries"][0]["ap"]["all"] == 1.0
    import csv

    rows = csv.DictReader(io.StringIO(request(f"{board.url}/leaderboard.csv")[1]))
    row = next(r for r in rows if r["method"] == "perfect oracle")
    assert row["ap_all"] == "1.0" and row["ci_all_low"] == "1.0" and row["ci_all_high"] == "1.0"
    # Pages show percent with one decimal.
    _, page = request(f"{board.url}/entry/{answer['id']}")
    assert '<td class="num ap">100.0' in page and "all: AP 100.0" in page
    _, ranking = request(f"{board.url}/")
    row_html = ranking.split(f'id="entry-{answer["id"]}"')[1].split("</tr>")[0]
    assert row_html.count('<td class="num ap">100.0') == sum(v is not None for v in done["ap"].values())
    assert "<small>[100.0, 100.0]</small>" in row_html


def test_hidden_labels_and_per_frame_results_are_never_served(board):
    gt = ground_truth()
    token = board.store.add_team("prober")
    document = submission(gt, seed=9, method="probe")
    _, answer = post_submission(board.url, token, document)
    wait_done(board.url, token, answer["id"])
    served = ""
    for path in ("/api/leaderboard", "/", f"/entry/{answer['id']}", "/leaderboard.csv", "/leaderboard.json",
                 f"/api/submissions/{answer['id']}"):
        status, text = request(board.url + path, token=token)
        assert status == 200
        served += text if isinstance(text, str) else json.dumps(text)
    labels = {f"{c[k]}"[:8] for cars in gt["frames"].values() for c in cars for k in ("x", "y")}
    assert not [v for v in labels if v in served]
    for frame_id in gt["frames"]:
        assert frame_id not in served
    for key in ('"counts"', '"tp"', '"fp"', '"gt"', "n_frames_ground_truth"):
        assert key not in served
    assert str(board.gt) not in served and str(board.db) not in served


def test_html_in_method_and_description_is_escaped(board):
    gt = ground_truth()
    token = board.store.add_team("<script>alert('team')</script>")
    attack = submission(
        gt, seed=11,
        method="<script>window.pwned=1</script>",
        description='"><img src=x onerror="window.pwned=2">',
        url='https://example.org/"><script>x()</script>',
    )
    _, answer = post_submission(board.url, token, attack)
    wait_done(board.url, token, answer["id"])
    for path in ("/", f"/entry/{answer['id']}"):
        _, page = request(board.url + path)
        assert "<script>window.pwned" not in page and "<img src=x" not in page and "<script>alert" not in page
        assert "&lt;script&gt;window.pwned=1&lt;/script&gt;" in page
        # The only scripts are the page's own, each carrying the response's nonce.
        assert page.count("<script") == page.count("<script nonce=")
    _, page = request(f"{board.url}/entry/{answer['id']}")
    assert "&quot;&gt;&lt;img src=x onerror=&quot;window.pwned=2&quot;&gt;" in page


def test_nothing_in_a_submission_names_a_file_on_the_server(board, tmp_path, monkeypatch):
    secret = tmp_path / "secret.json"
    secret.write_text('{"frames": {}}')
    gt = ground_truth()
    token = board.store.add_team("path-tricks")
    document = submission(gt, seed=13, method=str(secret), description=f"file://{secret}", url=f"https://x/{secret}")
    document["results"][str(secret)] = []
    document["results"]["../../../etc/passwd"] = []
    opened = []
    real_open = builtins.open
    monkeypatch.setattr(builtins, "open", lambda file, *a, **k: opened.append(str(file)) or real_open(file, *a, **k))
    monkeypatch.setattr(io, "open", builtins.open)
    status, answer = post_submission(board.url, token, document)
    monkeypatch.undo()
    assert status == 422
    assert any(f"{str(secret)!r} is not in the ground truth" in p for p in answer["problems"])
    assert not [path for path in opened if "secret" in path or "passwd" in path]
    for path in ("/entry/..%2F..%2Fetc%2Fpasswd", "/entry/../../etc/passwd", "/../../etc/passwd", "/entry/1.html"):
        status, _ = request(board.url + path)
        assert status == 404


def test_quota_is_three_per_rolling_30_days_and_counts_failures(board):
    gt = ground_truth()
    token = board.store.add_team("busy")
    team = board.store.team_for_token(token)
    ids = []
    for seed in range(3):
        status, answer = post_submission(board.url, token, submission(gt, seed=100 + seed, method=f"busy-{seed}"))
        assert status == 202
        ids.append(answer["id"])
    status, answer = post_submission(board.url, token, submission(gt, seed=200))
    assert status == 429 and "used its 3 submissions of the last 30 days" in answer["error"]
    for submission_id in ids:
        wait_done(board.url, token, submission_id)
    # A scorer failure still counts: mark one failed, the team is still at its quota.
    with sqlite3.connect(board.db) as db:
        db.execute("UPDATE submissions SET status = 'failed', error = 'x' WHERE id = ?", (ids[0],))
    assert post_submission(board.url, token, submission(gt, seed=201))[0] == 429
    # 31 days later the oldest submission no longer counts.
    with sqlite3.connect(board.db) as db:
        db.execute("UPDATE submissions SET submitted_at = submitted_at - 31 * 86400 WHERE id = ?", (ids[0],))
    status, answer = post_submission(board.url, token, submission(gt, seed=202))
    assert status == 202
    wait_done(board.url, token, answer["id"])
    assert board.store.submissions_in_window(team.id) == 3


def test_queued_submissions_report_their_position(tmp_path):
    gt = ground_truth()
    server = InProcessServer(tmp_path, gt, quota=10)
    try:
        server.scoring.stop()  # nothing is scored: the queue only grows
        token = server.store.add_team("queue")
        ids = [post_submission(server.url, token, submission(gt, seed=s))[1]["id"] for s in range(3)]
        positions = [request(f"{server.url}/api/submissions/{i}", token=token)[1]["position"] for i in ids]
        assert positions == [1, 2, 3]
    finally:
        server.http.shutdown()
        server.http.server_close()


def test_hidden_deleted_and_closed_round(tmp_path):
    from zendar_leaderboard.cli import main

    gt = ground_truth()
    server = InProcessServer(tmp_path, gt)
    try:
        token = server.store.add_team("admin-test")
        documents = [submission(gt, seed=s, method=f"m{s}") for s in (21, 22, 23)]
        ids = [post_submission(server.url, token, d)[1]["id"] for d in documents]
        for submission_id in ids:
            assert wait_done(server.url, token, submission_id)["status"] == "scored"
        assert main(["hide", str(ids[0]), "--db", str(server.db)]) == 0
        assert main(["delete", str(ids[1]), "--db", str(server.db)]) == 0
        entries = request(f"{server.url}/api/leaderboard")[1]["entries"]
        assert [e["id"] for e in entries] == [ids[2]]
        page = request(f"{server.url}/")[1]  # the cached page follows the administrator's commands
        assert 'id="entry-' + str(ids[2]) in page and f'id="entry-{ids[0]}"' not in page and f'id="entry-{ids[1]}"' not in page
        assert request(f"{server.url}/entry/{ids[0]}")[0] == 404
        assert main(["delete", "999", "--db", str(server.db)]) == 2

        public = expected_ap(gt, documents[2], server.test_split.public_frame_ids)
        private = expected_ap(gt, documents[2], server.test_split.private_frame_ids)
        assert public != private
        assert entries[0]["ap"] == public
        assert main(["close-round", "--db", str(server.db)]) == 0
        board_json = request(f"{server.url}/api/leaderboard")[1]
        assert board_json["round"] == {"closed": True, "shown": "private"}
        assert board_json["entries"][0]["ap"] == private and board_json["entries"][0]["ap_public"] == public
        status, answer = post_submission(server.url, token, submission(gt, seed=24))
        assert status == 403 and "round is closed" in answer["error"]
        _, page = request(f"{server.url}/entry/{ids[2]}")
        assert "Private part" in page and "Public part" in page
    finally:
        server.stop()


@pytest.mark.slow
def test_a_protocol_change_rescores_everything_once(tmp_path):
    gt = ground_truth()
    server = InProcessServer(tmp_path, gt)
    token = server.store.add_team("rescore")
    document = submission(gt, seed=31)
    submission_id = post_submission(server.url, token, document)[1]["id"]
    wait_done(server.url, token, submission_id)
    server.stop()
    # The score on record was computed under an older protocol.
    with sqlite3.connect(server.db) as db:
        db.execute("UPDATE scores SET protocol_version = '0.9', public = ?", (json.dumps({"ap": {}}),))
    server = InProcessServer(tmp_path, gt)
    try:
        done = wait_done(server.url, token, submission_id)
        assert done["ap"] == expected_ap(gt, document, server.test_split.public_frame_ids)
        assert server.store.score(submission_id).protocol_version == "1.0"
        assert server.store.submission(submission_id).scoring_runs == 2
        assert server.store.submissions_in_window(server.store.team_for_token(token).id) == 1
    finally:
        server.stop()


@pytest.mark.slow
def test_scoring_over_the_time_limit_fails_with_a_reason_and_counts(tmp_path):
    gt = ground_truth(n_scenes=8, frames_per_scene=10)
    # 100,000 bootstrap resamples take far longer than 0.5 s.
    server = InProcessServer(tmp_path, gt, bootstrap=100_000, time_limit_s=0.5)
    try:
        token = server.store.add_team("slow")
        submission_id = post_submission(server.url, token, submission(gt, seed=41))[1]["id"]
        done = wait_done(server.url, token, submission_id, timeout_s=300)
        assert done == {**done, "status": "failed", "error": "scoring took longer than the limit of 0.5 s"}
        assert server.store.submissions_in_window(server.store.team_for_token(token).id) == 1
    finally:
        server.stop()


@pytest.mark.slow
def test_a_scorer_that_dies_fails_its_submission_and_a_fresh_one_takes_the_next(tmp_path):
    import os
    import signal
    import time

    def wait_status(submission_id, status):
        deadline = time.monotonic() + 120
        while server.store.submission(submission_id).status != status:
            assert time.monotonic() < deadline, (submission_id, status)
            time.sleep(0.05)

    gt = ground_truth(n_scenes=8, frames_per_scene=10)
    server = InProcessServer(tmp_path, gt, bootstrap=100_000, quota=5)
    try:
        token = server.store.add_team("crashy")
        first = post_submission(server.url, token, submission(gt, seed=51))[1]["id"]
        second = post_submission(server.url, token, submission(gt, seed=52))[1]["id"]
        wait_status(first, "scoring")
        # What the kernel's out-of-memory killer does to a scorer.
        (scorer,) = server.scoring._scorers
        os.kill(scorer.process.pid, signal.SIGKILL)
        done = wait_done(server.url, token, first, timeout_s=120)
        assert done["status"] == "failed"
        assert done["error"] == "the scorer stopped while scoring this submission (memory limit 4096 MB)"
        wait_status(second, "scoring")
        (fresh,) = server.scoring._scorers
        assert fresh.process.pid != scorer.process.pid
    finally:
        server.stop()  # the second goes back to the queue
    assert server.store.submission(second).status == "queued"
    server = InProcessServer(tmp_path, gt, bootstrap=0, quota=5)
    try:
        assert wait_done(server.url, token, second)["status"] == "scored"
        assert server.store.submission(first).status == "failed"  # failures are final, never retried
    finally:
        server.stop()


@pytest.mark.parametrize("error", [BrokenPipeError, ConnectionResetError])
def test_a_client_that_hangs_up_before_its_answer_is_not_a_server_error(board, monkeypatch, error):
    from zendar_leaderboard.server import Handler

    def hung_up(self, answer):
        raise error(32, "the client hung up")

    errors = []
    monkeypatch.setattr(Handler, "_write_answer", hung_up)
    monkeypatch.setattr(board.http, "handle_error", lambda request, address: errors.append(address))
    answer = raw_exchange(board.url, b"GET /api/ranking HTTP/1.1\r\nHost: x\r\n\r\n", read_timeout_s=5.0)
    assert answer == b"" and errors == []
