"""Submission rules, the public/private division and the shown scores (no server)."""

from __future__ import annotations

import json
import time

import pytest

from tests.leaderboard.conftest import ground_truth, meta, submission
from zendar_leaderboard.ground_truth import divide_frames, frames_sha256
from zendar_leaderboard.scoring import format_ap_percent, score_submission, shown_ap
from zendar_leaderboard.submission import check_submission


def body(document) -> bytes:
    return json.dumps(document).encode()


def test_a_valid_submission_passes_and_keeps_only_known_meta():
    gt = ground_truth()
    document = submission(gt)
    document["meta"]["favourite_colour"] = "blue"
    checked = check_submission(body(document), list(gt["frames"]))
    assert checked.ok, checked.problems
    assert "favourite_colour" not in checked.meta and checked.meta["method"] == "noisy oracle"


def test_a_frame_id_given_twice_is_a_problem_not_a_silent_loss():
    gt = ground_truth()
    document = submission(gt)
    first = next(iter(document["results"]))
    text = json.dumps(document)
    doubled = text[:-2] + f', "{first}": []' + text[-2:]  # the same frame again, empty, at the end of results
    checked = check_submission(doubled.encode(), list(gt["frames"]))
    assert not checked.ok
    assert any(first in problem and "2 times" in problem for problem in checked.problems), checked.problems


def test_every_meta_problem_is_listed_at_once():
    gt = ground_truth()
    document = submission(gt)
    document["meta"] = {
        "method": "m" * 41,
        "team": "",
        "description": 7,
        "url": "javascript:alert(1)",
        "uses_sar": "yes",
        "uses_camera": 1,
        "runtime_ms": 1e300,
        "hardware": "gpu\x00",
    }
    problems = check_submission(body(document), list(gt["frames"])).problems
    expected = [
        "'method' has 41 characters, more than the limit of 40",
        "'team' is empty",
        "missing 'contact'",
        "'description' must be a string, got int",
        "'url' must start with http:// or https://",
        "'uses_sar' must be true or false, got str",
        "'uses_camera' must be true or false, got int",
        "missing 'uses_lidar'",
        "missing 'external_data'",
        "missing 'uses_supervised'",
        "missing 'uses_unsupervised_pretraining'",
        "'runtime_ms' must lie in [0, 86400000]",
        "'hardware' contains control characters",
    ]
    for text in expected:
        assert any(text in p for p in problems), (text, problems)
    assert len(problems) == len(expected)


def test_meta_and_detection_problems_come_together_with_frame_set_problems():
    gt = ground_truth()
    frame_ids = list(gt["frames"])
    document = submission(gt)
    del document["meta"]["runtime_ms"]
    del document["results"][frame_ids[0]]
    document["results"][frame_ids[1]][0]["score"] = "high"
    document["results"]["elsewhere/1"] = []
    problems = check_submission(body(document), frame_ids).problems
    assert len(problems) == 4, problems
    assert any("runtime_ms" in p for p in problems)
    assert any(f"{frame_ids[0]!r} is missing from predictions" in p for p in problems)
    assert any(f"{frame_ids[1]!r} detection 0: 'score' must be a number" in p for p in problems)
    assert any("'elsewhere/1' is not in the ground truth" in p for p in problems)


@pytest.mark.parametrize(
    "raw",
    [b"[" * 200_000, b'{"a":' * 5_000 + b"1" + b"}" * 5_000, b'{"meta": ' + b"[" * 2_000 + b"]" * 2_000 + b"}"],
    ids=["open-brackets", "deep-objects", "deep-meta"],
)
def test_nesting_bombs_are_refused_with_one_clear_problem(raw):
    started = time.process_time()
    checked = check_submission(raw)
    assert checked.problems and "nested more than 1024 levels deep" in checked.problems[0]
    assert len(checked.problems) == 1
    assert time.process_time() - started < 5  # refused by the parser, not by walking the tree


@pytest.mark.parametrize(
    "number", [b"1e400", b"-1e999", b"1" + b"0" * 400, b"9" * 1_000_000, b"-12345678901234567890", b"1" + b"0" * 25]
)
def test_numbers_too_large_for_a_double_are_refused(number):
    gt = ground_truth(n_scenes=1, frames_per_scene=1)
    frame_id = next(iter(gt["frames"]))
    raw = b'{"meta": %s, "results": {"%s": [{"x": %s, "y": 1.0, "score": 0.5}]}}' % (
        json.dumps(meta()).encode(), frame_id.encode(), number)
    problems = check_submission(raw, [frame_id]).problems
    assert len(problems) == 1, problems
    assert "too large for a double" in problems[0] or "more than 19 digits" in problems[0], problems
    assert len(problems[0]) < 200  # the number is not quoted back


def test_integers_up_to_19_digits_and_digits_inside_strings_pass():
    gt = {"frames": {"scene-1/1600000000000000000000000": [{"x": 1.0, "y": 2.0}]}}
    frame_id = next(iter(gt["frames"]))
    raw = b'{"meta": %s, "results": {"%s": [{"x": 1234567890123456789, "y": 1.0, "score": 0.5}]}}' % (
        json.dumps(meta(description="serial 123456789012345678901234567890")).encode(), frame_id.encode())
    assert check_submission(raw, [frame_id]).ok


def test_nan_literals_and_broken_json_are_refused():
    assert "not valid JSON" in check_submission(b'{"meta": {}, "results": {"s/1": [{"x": NaN}]}}').problems[0]
    assert "not valid JSON" in check_submission(b'{"meta": ').problems[0]
    assert "expected a JSON object" in check_submission(b"[1, 2]").problems[0]


def test_parts_are_whole_scenes_disjoint_and_cover_the_split():
    gt = ground_truth(n_scenes=5)
    frame_ids = list(gt["frames"])
    public, private = divide_frames(frame_ids)
    assert set(public) | set(private) == set(frame_ids) and not set(public) & set(private)
    scenes = lambda ids: {f.rpartition("/")[0] for f in ids}  # noqa: E731
    assert len(scenes(public)) == 3 and len(scenes(private)) == 2
    assert not scenes(public) & scenes(private)
    assert divide_frames(list(reversed(frame_ids))) == (tuple(reversed(public)), tuple(reversed(private)))


def test_a_single_scene_is_divided_in_time_not_as_strings():
    frame_ids = ["s/1000", "s/900", "s/1100", "s/800", "s/1200"]
    public, private = divide_frames(frame_ids)
    assert public == ("s/1000", "s/900", "s/800") and private == ("s/1100", "s/1200")


def test_the_checksum_ignores_key_order_but_not_labels():
    gt = ground_truth()
    reordered = dict(reversed(list(gt["frames"].items())))
    assert frames_sha256(reordered) == frames_sha256(gt["frames"])
    moved = json.loads(json.dumps(gt["frames"]))
    first = next(iter(moved))
    moved[first][0]["x"] += 0.01
    assert frames_sha256(moved) != frames_sha256(gt["frames"])


def test_shown_score_of_a_hand_worked_case():
    from zendar_leaderboard.ground_truth import TestSplit

    # Public part: scene a (two cars near, one mid). Predictions by score: TP 0.9, FP 0.8, TP 0.7 in
    # near -> near AP = 1/2 * 1 + 1/2 * 2/3 = 0.8333 -> 0.833 (page: 83.3); the mid car is missed -> mid AP 0.
    # 'all': G = 3, TP at 0.9 (P 1, R 1/3), FP 0.8, TP 0.7 (P 2/3, R 2/3) -> 1/3 + 1/3 * 2/3 = 0.5556 -> 0.556
    # (page: 55.6).
    frames = {
        "a/100": [{"x": 0.0, "y": 10.0}, {"x": -8.0, "y": -3.0}, {"x": 20.0, "y": -5.0}],
        "b/100": [{"x": -40.0, "y": 2.0}],
    }
    split = TestSplit(frames, "test", frames_sha256(frames), ("a/100",), ("b/100",))
    document = {
        "meta": meta(),
        "results": {
            "a/100": [
                {"x": 0.5, "y": 9.0, "score": 0.9},
                {"x": 5.0, "y": 5.0, "score": 0.8},
                {"x": -7.0, "y": -2.0, "score": 0.7},
            ],
            "b/100": [{"x": -40.0, "y": 3.0, "score": 0.4}],
        },
    }
    scores = score_submission(document, split, bootstrap=0)
    # AP is a fraction in [0, 1] rounded to 0.001, written without float artefacts.
    assert scores["public"]["ap"] == {"near": 0.833, "mid": 0.0, "far": None, "all": 0.556}
    assert json.dumps(scores["public"]["ap"]) == '{"near": 0.833, "mid": 0.0, "far": null, "all": 0.556}'
    assert scores["private"]["ap"] == {"near": None, "mid": None, "far": 1.0, "all": 1.0}
    assert scores["public"]["ci"] is None  # one scene: no interval
    assert set(scores["public"]) == {"ap", "ci", "pr_curves", "n_frames"}  # no counts, nothing per frame
    assert scores["gt_sha256"] == split.sha256 and scores["protocol_version"] == "1.0"

    # The pages show the same score in percent with one decimal.
    from zendar_leaderboard.pages import entry_page, ranking_page

    entry = {
        "id": 1, "rank": 1, "method": "hand", "team": "workers", "ap": scores["public"]["ap"],
        "ci": {"near": [0.8, 0.9], "mid": [0.0, 0.05], "far": None, "all": [0.5, 0.6]},
        "meta": {"runtime_ms": 1}, "submitted_at": "2026-01-01T00:00:00Z", "part": "public",
        "protocol_version": "1.0", "evaluator_version": "x", "submission_sha256": "s", "gt_sha256": "g",
    }
    board = {"entries": [entry], "round": {"closed": False, "shown": "public"}, "sorted_by": "all"}
    ranking = ranking_page(board, entry_href=lambda i: f"/entry/{i}", static=False)
    cells = ("83.3<small>[80.0, 90.0]</small>", "0.0<small>[0.0, 5.0]</small>", "–", "55.6<small>[50.0, 60.0]</small>")
    assert "".join(f'<td class="num ap">{cell}</td>' for cell in cells) in ranking
    assert 'data-apnear="0.833"' in ranking and 'data-apfar=""' in ranking  # sorting reads the fractions
    page = entry_page(entry, {"public": scores["public"]}, static=False)
    assert '<td class="num ap">83.3</td>' in page and '<td class="num ap">55.6</td>' in page
    assert '<td class="num ap">0.0</td>' in page and '<td class="num ap">–</td>' in page
    assert "near: AP 83.3" in page and "0.833" not in page.split("<svg")[0]


def test_shown_ap_is_a_fraction_rounded_to_a_thousandth():
    assert shown_ap(0.83333) == 0.833 and shown_ap(0.55556) == 0.556 and shown_ap(1.0) == 1.0
    assert shown_ap(0.0) == 0.0 and shown_ap(None) is None
    assert shown_ap(0.1 + 0.2) == 0.3 and repr(shown_ap(0.1 + 0.2)) == "0.3"  # no float artefacts
    assert all(repr(shown_ap(k / 1000 + 1e-9)) == repr(k / 1000) for k in range(1001))


def test_percent_is_formatted_from_the_stored_fraction():
    assert format_ap_percent(0.833) == "83.3" and format_ap_percent(0.556) == "55.6"
    assert format_ap_percent(1.0) == "100.0" and format_ap_percent(0.0) == "0.0"
    assert format_ap_percent(None) == "–" and format_ap_percent(None, "n/a") == "n/a"
    # Every stored value shows as exactly its own tenth of a point (0.007 is 0.7, 0.29 is 29.0 ...).
    assert all(format_ap_percent(shown_ap(k / 1000)) == f"{k // 10}.{k % 10}" for k in range(1001))


def test_labels_from_a_dataset_root_and_from_export_gt_have_one_checksum(tmp_path):
    from tests.eval.test_eval_dataset_root import frame, make_dataset
    from zendar_dataset.format.ground_truth import export_ground_truth
    from zendar_leaderboard.ground_truth import load_test_split

    root = make_dataset(tmp_path / "ds", test_labelled=True)
    export_ground_truth(root, "test", tmp_path / "gt.json")
    from_root = load_test_split(root, "test")
    from_file = load_test_split(tmp_path / "gt.json")
    assert from_root.sha256 == from_file.sha256 and from_root.split == "test"
    # One scene of two frames: the earlier frame is public, the later private.
    assert from_root.public_frame_ids == (frame("t0", 0),) and from_root.private_frame_ids == (frame("t0", 1),)
    from zendar_dataset.errors import ZendarError

    with pytest.raises(ZendarError, match="labels withheld"):
        load_test_split(make_dataset(tmp_path / "unlabelled", test_labelled=False), "test")
