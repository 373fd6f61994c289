"""A real ``zendar-leaderboard serve`` process: 50 teams at once, and a crash in the middle of scoring."""

from __future__ import annotations

import sqlite3
import time
from concurrent.futures import ThreadPoolExecutor

import pytest

from tests.leaderboard.conftest import ground_truth_file, start_server, submission
from tests.leaderboard.helpers import expected_ap, post_submission, wait_done
from zendar_leaderboard.ground_truth import divide_frames
from zendar_leaderboard.store import Store


@pytest.mark.slow
def test_fifty_concurrent_submissions_from_fifty_teams_are_each_recorded_and_scored_once(tmp_path):
    gt, gt_path = ground_truth_file(tmp_path)
    db = tmp_path / "board.db"
    store = Store(db)
    tokens = [store.add_team(f"team-{k:02d}") for k in range(50)]
    documents = [submission(gt, seed=1000 + k, method=f"method-{k:02d}") for k in range(50)]
    server = start_server(db, gt_path, "--bootstrap", "10")
    try:
        with ThreadPoolExecutor(max_workers=50) as pool:
            answers = list(pool.map(lambda k: post_submission(server.url, tokens[k], documents[k]), range(50)))
        assert [status for status, _ in answers] == [202] * 50
        ids = [answer["id"] for _, answer in answers]
        assert len(set(ids)) == 50
        public = divide_frames(list(gt["frames"]))[0]
        for k, submission_id in enumerate(ids):
            done = wait_done(server.url, tokens[k], submission_id, timeout_s=300)
            assert done["status"] == "scored"
            assert done["ap"] == expected_ap(gt, documents[k], public)
    finally:
        server.stop()
    with sqlite3.connect(db) as connection:
        rows = connection.execute(
            "SELECT t.name, s.status, s.scoring_runs, (SELECT COUNT(*) FROM scores c WHERE c.submission_id = s.id), "
            "json_extract(s.meta, '$.method') FROM submissions s JOIN teams t ON t.id = s.team_id ORDER BY t.name"
        ).fetchall()
    assert rows == [(f"team-{k:02d}", "scored", 1, 1, f"method-{k:02d}") for k in range(50)]


@pytest.mark.slow
def test_a_server_killed_while_scoring_loses_nothing_and_scores_the_rest_on_restart(tmp_path):
    gt, gt_path = ground_truth_file(tmp_path, n_scenes=8, frames_per_scene=10)
    db = tmp_path / "board.db"
    store = Store(db)
    tokens = [store.add_team(f"crash-{k}") for k in range(4)]
    documents = [submission(gt, seed=2000 + k) for k in range(4)]
    # 100,000 resamples make each scoring last seconds: the kill lands in the middle of one.
    server = start_server(db, gt_path, "--bootstrap", "100000")
    ids = [post_submission(server.url, tokens[k], documents[k])[1]["id"] for k in range(4)]
    deadline = time.monotonic() + 120
    while store.submission(ids[0]).status != "scoring":
        assert time.monotonic() < deadline, "scoring never started"
        time.sleep(0.05)
    server.kill()
    statuses = [store.submission(i).status for i in ids]
    assert statuses[0] == "scoring" and statuses[1:] == ["queued"] * 3
    assert all(store.score(i) is None for i in ids)  # no half-recorded score

    server = start_server(db, gt_path, "--bootstrap", "10")
    try:
        public = divide_frames(list(gt["frames"]))[0]
        for k, submission_id in enumerate(ids):
            done = wait_done(server.url, tokens[k], submission_id, timeout_s=300)
            assert done["status"] == "scored" and done["ap"] == expected_ap(gt, documents[k], public)
    finally:
        server.stop()
    assert [store.submission(i).scoring_runs for i in ids] == [2, 1, 1, 1]
    assert "requeued 1" in server.log.read_text()
