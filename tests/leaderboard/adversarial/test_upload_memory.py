"""An upload's memory is measured, not timed: the peak of checking it stays within 40 times its size,
whatever it holds, and problems past the listed ones are counted, not built."""

from __future__ import annotations

import json
import tracemalloc

import pytest

from tests.leaderboard.conftest import ground_truth, meta, submission
from tests.leaderboard.helpers import post_submission
from zendar_dataset.eval.validation import read_predictions
from zendar_leaderboard.routes import MAX_PROBLEMS
from zendar_leaderboard.server import ServerSettings
from zendar_leaderboard.submission import DEFAULT_MAX_BYTES, MEMORY_PER_UPLOAD_BYTE, check_submission

GT_FRAME_IDS = list(ground_truth()["frames"])
MB = 1_000_000


def _results_body(items: bytes, size_bytes: int) -> bytes:
    """``{"meta": {}, "results": {...}}`` of about ``size_bytes`` around ``items`` repeated."""
    return b'{"meta":{},"results":{' + items * (size_bytes // len(items)) + b'"scene-00/900000000":[]}}'


def _detections_body(detection: bytes, size_bytes: int) -> bytes:
    """One frame whose list holds ``detection`` repeated to about ``size_bytes``."""
    return b'{"meta":{},"results":{"scene-00/900000000":[' + (detection + b",") * (size_bytes // (len(detection) + 1)) + b"{}]}}"


def _unknown_frames_body(size_bytes: int) -> bytes:
    frames = b",".join(b'"f%d":[]' % i for i in range(size_bytes // 10))
    return b'{"meta":{},"results":{' + frames + b"}}"


def _peak_bytes(body: bytes) -> int:
    """Peak memory of the server's check of ``body``, the body itself included."""
    tracemalloc.start()
    try:
        checked = check_submission(body, GT_FRAME_IDS, max_problems=MAX_PROBLEMS)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert not checked.ok
    return peak + len(body)


HOSTILE = {
    "empty-objects": lambda size: _detections_body(b"{}", size),
    "one-key-objects": lambda size: _detections_body(b'{"a":0.5}', size),
    "empty-lists": lambda size: _detections_body(b"[]", size),
    "unknown-frames": _unknown_frames_body,
    "frames-not-lists": lambda size: _results_body(b'"a":0,', size),
}


@pytest.mark.parametrize("size_bytes", [1 * MB, 3 * MB], ids=["1MB", "3MB"])
@pytest.mark.parametrize("shape", HOSTILE)
def test_checking_a_hostile_upload_takes_at_most_40_times_its_size(shape, size_bytes):
    body = HOSTILE[shape](size_bytes)
    assert _peak_bytes(body) <= MEMORY_PER_UPLOAD_BYTE * len(body)


def test_checking_a_dense_valid_upload_takes_at_most_40_times_its_size():
    gt = {"frames": {f"scene-{k:04d}/{1_600_000_000_000_000_000 + k}": [] for k in range(20_000)}}
    results = {frame_id: [{"x": 1.5, "y": -2.25, "score": 0.5}] * 5 for frame_id in gt["frames"]}
    body = json.dumps({"meta": meta(), "results": results}, separators=(",", ":")).encode()
    tracemalloc.start()
    try:
        checked = check_submission(body, list(gt["frames"]), max_problems=MAX_PROBLEMS)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert checked.ok and len(body) > 2 * MB
    assert peak + len(body) <= MEMORY_PER_UPLOAD_BYTE * len(body)


def test_problems_past_the_cap_are_counted_not_listed():
    body = _detections_body(b"{}", 60_000)  # 20,000 empty detections: 60,000 problems
    everything = check_submission(body, GT_FRAME_IDS)
    capped = check_submission(body, GT_FRAME_IDS, max_problems=MAX_PROBLEMS)
    assert len(capped.problems) == MAX_PROBLEMS
    assert capped.problems == everything.problems[:MAX_PROBLEMS]
    assert capped.problem_count == len(everything.problems) > 60_000


def test_the_evaluators_validator_lists_every_problem_unless_capped():
    document = {"meta": {}, "results": {"s/1": [{}] * 300, "s/2": [{}] * 400, "s/3": "not a list"}}
    everything = read_predictions(document)
    assert len(everything.problems) == 1 + 3 * 700 and everything.problems_not_listed == 0
    capped = read_predictions(document, max_problems=10)
    assert capped.problems == everything.problems[:10] and capped.problems_not_listed == 1 + 3 * 700 - 10
    assert capped.table is None and read_predictions(document, max_problems=0).table is None


def test_a_refused_upload_lists_the_first_problems_and_says_how_many_more(board):
    token = board.store.add_team("many-problems")
    document = submission(ground_truth())
    document["results"]["scene-00/900000000"] = [{}] * 400  # 1,200 problems, under the density rule's size
    status, answer = post_submission(board.url, token, document)
    assert status == 422
    assert answer["error"].startswith("1,200 problems")
    assert len(answer["problems"]) == MAX_PROBLEMS + 1
    assert answer["problems"][-1] == "... and 200 more problems"


def test_the_default_size_limit_fits_the_checking_slots_in_2_gb(tmp_path):
    from zendar_leaderboard.ground_truth import load_test_split
    from zendar_leaderboard.store import Store

    gt = tmp_path / "gt.json"
    gt.write_text(json.dumps(ground_truth()))
    settings = ServerSettings(Store(tmp_path / "b.db"), load_test_split(gt), None, quota=3, max_bytes=DEFAULT_MAX_BYTES)
    assert settings.parallel_checks * MEMORY_PER_UPLOAD_BYTE * DEFAULT_MAX_BYTES <= 2_000_000_000
    # A 100,000-frame test split (about 20 MB) still fits under the limit.
    assert DEFAULT_MAX_BYTES >= 20_000_000
