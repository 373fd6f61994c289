"""Every bad input is reported, all problems at once, each naming its frame and detection index."""

import json
import math

import pytest

from zendar_dataset.errors import PredictionsError
from zendar_dataset.eval import evaluate

GT = {"frames": {"s/1": [{"x": 5.0, "y": 0.0}], "s/2": []}}


def good_results():
    return {"s/1": [{"x": 5.0, "y": 0.0, "score": 0.9}], "s/2": []}


def problems_of(predictions, ground_truth=GT, **kwargs):
    with pytest.raises(PredictionsError) as info:
        evaluate(predictions, ground_truth, **kwargs)
    return info.value.problems


@pytest.mark.parametrize(
    ("detection", "expected"),
    [
        ([1, 2, 3], "detection 0: expected an object"),
        ({"y": 0.0, "score": 0.5}, "detection 0: missing 'x'"),
        ({"x": 0.0, "score": 0.5}, "detection 0: missing 'y'"),
        ({"x": 0.0, "y": 0.0}, "detection 0: missing 'score'"),
        ({"x": "1.0", "y": 0.0, "score": 0.5}, "detection 0: 'x' must be a number, got str"),
        ({"x": 1.0, "y": None, "score": 0.5}, "detection 0: 'y' must be a number, got null"),
        ({"x": 1.0, "y": 0.0, "score": True}, "detection 0: 'score' must be a number, got bool"),
        ({"x": math.nan, "y": 0.0, "score": 0.5}, "detection 0: 'x' is not finite (nan)"),
        ({"x": 1.0, "y": math.inf, "score": 0.5}, "detection 0: 'y' is not finite (inf)"),
        ({"x": 1.0, "y": 0.0, "score": -math.inf}, "detection 0: 'score' is not finite (-inf)"),
        ({"x": 10**400, "y": 0.0, "score": 0.5}, "detection 0: 'x' is too large"),
        ({"x": 1.0, "y": 0.0, "score": 0.5, "yaw": "north"}, "detection 0: 'yaw' must be a number"),
        ({"x": 1.0, "y": 0.0, "score": 0.5, "vx": math.nan}, "detection 0: 'vx' is not finite"),
    ],
)
def test_bad_detection_is_named(detection, expected):
    results = good_results()
    results["s/2"] = [detection]
    problems = problems_of({"results": results})
    assert len(problems) == 1
    assert problems[0].startswith("predictions frame 's/2' ")
    assert expected in problems[0]


def test_all_problems_are_collected():
    results = {
        "s/1": [
            {"x": 5.0, "y": 0.0, "score": 0.9},
            {"x": math.nan, "y": "a"},  # three problems in one detection
            "oops",
        ],
        "nope/7": [],
        "s/3": {"x": 1},
    }
    problems = problems_of({"meta": [], "results": results})
    expected = [
        "'meta' must be an object",
        "frame 's/3': expected a list of detections, got dict",
        "frame 's/1' detection 1: 'x' is not finite",
        "frame 's/1' detection 1: 'y' must be a number, got str",
        "frame 's/1' detection 1: missing 'score'",
        "frame 's/1' detection 2: expected an object",
        "predictions frame 'nope/7' is not in the ground truth",
        "predictions frame 's/3' is not in the ground truth",
        "ground truth frame 's/2' is missing from predictions",
    ]
    assert len(problems) == len(expected)
    for text in expected:
        assert any(text in p for p in problems), text


def test_more_than_500_detections_in_a_frame():
    results = good_results()
    results["s/2"] = [{"x": 1.0, "y": float(i), "score": 0.5} for i in range(501)]
    assert problems_of({"results": results}) == [
        "predictions frame 's/2': 501 detections, more than the limit of 500 per frame"
    ]
    results["s/2"] = results["s/2"][:500]
    # 500 is allowed. Detections at (1, y), all in frame s/2 without ground truth, are FPs in "all"
    # while r = sqrt(1 + y²) < 60, i.e. for y = 0 .. 59.
    assert evaluate({"results": results}, GT)["counts"]["all"]["fp"] == 60


@pytest.mark.parametrize(
    ("document", "expected"),
    [
        ([], "expected a JSON object with 'meta' and 'results', got list"),
        ({"meta": {"method": "m"}}, "missing 'results'"),
        ({"results": []}, "'results' must be an object"),
        ({"meta": {"method": 3}, "results": good_results()}, "'meta.method' must be a string"),
    ],
)
def test_bad_document_shape(document, expected):
    problems = problems_of(document)
    assert any(expected in p for p in problems), problems


def test_not_json_and_size_limit(tmp_path):
    path = tmp_path / "p.json"
    path.write_text("{not json")
    assert "is not valid JSON" in problems_of(path)[0]
    path.write_text(json.dumps({"results": good_results()}))
    size = path.stat().st_size
    problems = problems_of(path, max_bytes=size - 1)
    assert len(problems) == 1 and f"over the limit of {size - 1:,} bytes" in problems[0]
    assert evaluate(path, GT, max_bytes=size)["counts"]["near"]["tp"] == 1
    assert "does not exist" in problems_of(tmp_path / "missing.json")[0]


def test_nan_literals_in_a_file_are_non_finite_values(tmp_path):
    path = tmp_path / "p.json"
    path.write_text('{"results": {"s/1": [{"x": NaN, "y": Infinity, "score": -Infinity}], "s/2": []}}')
    problems = problems_of(path)
    assert problems == [
        "predictions frame 's/1' detection 0: 'x' is not finite (nan)",
        "predictions frame 's/1' detection 0: 'y' is not finite (inf)",
        "predictions frame 's/1' detection 0: 'score' is not finite (-inf)",
    ]


def test_ground_truth_is_validated_the_same_way_and_together():
    ground_truth = {"frames": {"s/1": [{"x": 1.0}, {"x": math.inf, "y": 0.0}, 4], "s/2": "none"}}
    problems = problems_of({"results": {"s/1": [{"x": "a", "y": 0, "score": 1}]}}, ground_truth)
    for text in [
        "ground truth frame 's/1' detection 0: missing 'y'",
        "ground truth frame 's/1' detection 1: 'x' is not finite",
        "ground truth frame 's/1' detection 2: expected an object",
        "ground truth frame 's/2': expected a list",
        "predictions frame 's/1' detection 0: 'x' must be a number",
        "ground truth frame 's/2' is missing from predictions",
    ]:
        assert any(text in p for p in problems), (text, problems)
    assert "missing 'frames'" in problems_of({"results": {}}, {"labels": {}})[0]
    assert "expected a JSON object with 'frames'" in problems_of({"results": {}}, [1])[0]


def test_partial_allows_missing_frames_but_not_unknown_ones():
    results = {"s/1": [{"x": 5.0, "y": 0.0, "score": 0.9}]}
    metrics = evaluate({"results": results}, GT, partial=True)
    assert metrics["partial"] is True
    assert metrics["n_frames"] == 1
    assert metrics["n_frames_ground_truth"] == 2
    assert "missing from predictions" in problems_of({"results": results})[0]
    results["x/9"] = []
    assert problems_of({"results": results}, partial=True) == [
        "predictions frame 'x/9' is not in the ground truth"
    ]


def test_partial_scores_only_the_present_frames():
    ground_truth = {"frames": {"s/1": [{"x": 5.0, "y": 0.0}], "s/2": [{"x": 20.0, "y": 0.0}]}}
    metrics = evaluate({"results": {"s/1": [{"x": 5.0, "y": 0.0, "score": 0.9}]}}, ground_truth, partial=True)
    assert metrics["counts"]["mid"]["gt"] == 0  # s/2's ground truth is not counted
    assert metrics["ap"]["near"] == 1.0 and metrics["ap"]["mid"] is None


@pytest.mark.parametrize(
    ("bad", "expected"),
    [
        ({"yaw": True}, "'yaw' must be a number, got bool"),
        ({"length": math.inf}, "'length' is not finite"),
        ({"vy": 10**400}, "'vy' is too large"),
    ],
)
def test_optional_fields_on_every_detection_are_checked_column_wise(bad, expected):
    # Every detection carries optional fields (the common case): valid ones score as if absent,
    # and one bad value among them is still named by frame and index.
    extra = {"length": 4.5, "width": 1.8, "yaw": 0.1, "vx": 3.0, "vy": -1, "note": "ignored"}
    plain = {f"s/{k}": [{"x": 5.0 + i, "y": 0.0, "score": 0.1 * i} for i in range(3)] for k in range(4)}
    frames = {"frames": {frame_id: [{"x": 5.0, "y": 0.0}] for frame_id in plain}}
    rich = {f: [dict(d, **extra) for d in detections] for f, detections in plain.items()}
    assert evaluate({"results": rich}, frames)["ap"] == evaluate({"results": plain}, frames)["ap"]
    rich["s/2"][1].update(bad)
    problems = problems_of({"results": rich}, frames)
    assert len(problems) == 1
    assert problems[0].startswith("predictions frame 's/2' detection 1: ")
    assert expected in problems[0]


@pytest.mark.parametrize("text", ['{"results": {}}', '{"results": {"s/1": [{"x": NaN}]}}', "{broken"])
@pytest.mark.parametrize("enabled", [True, False])
def test_parsing_leaves_the_garbage_collector_as_it_found_it(tmp_path, text, enabled):
    import gc

    from zendar_dataset.eval.validation import load_document

    path = tmp_path / "p.json"
    path.write_text(text)
    was = gc.isenabled()
    try:
        gc.enable() if enabled else gc.disable()
        load_document(path, what="predictions")
        assert gc.isenabled() is enabled
    finally:
        gc.enable() if was else gc.disable()
