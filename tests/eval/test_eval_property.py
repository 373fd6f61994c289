"""The package against the plain reference in eval_reference.py, on random inputs built to hit
ties, exact 2.5 m distances and band edges (coordinates on a 0.5 m grid, few distinct scores)."""

import random

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.eval.eval_reference import reference_evaluate
from zendar_dataset.eval import evaluate

coordinate = st.one_of(
    st.integers(-130, 130).map(lambda k: k * 0.5),  # grid: exact distances of 2.5 m, edges 15/30/60
    st.floats(-70.0, 70.0, allow_nan=False, allow_infinity=False),
)
score = st.one_of(st.sampled_from([0.1, 0.5, 0.5, 0.9]), st.floats(0.0, 1.0))


@st.composite
def scenes(draw):
    n_frames = draw(st.integers(1, 6))
    frames, results = {}, {}
    for k in range(n_frames):
        frame_id = f"scene{draw(st.integers(0, 2))}/{k}"
        anchors = draw(st.lists(st.tuples(coordinate, coordinate), max_size=6))
        frames[frame_id] = [{"x": x, "y": y} for x, y in anchors]
        detections = []
        for _ in range(draw(st.integers(0, 8))):
            if anchors and draw(st.booleans()):
                # Near an anchor: offsets on the grid give distances of exactly 2.5 m (1.5, 2.0).
                x, y = draw(st.sampled_from(anchors))
                dx, dy = draw(st.sampled_from([(0, 0), (1.5, 2.0), (2.5, 0), (0, -2.0), (1.0, 1.0), (-3, 0)]))
                x, y = x + dx, y + dy
            else:
                x, y = draw(coordinate), draw(coordinate)
            detections.append({"x": x, "y": y, "score": draw(score)})
        results[frame_id] = detections
    return frames, results


@settings(max_examples=200, deadline=None)
@given(scenes())
def test_package_matches_reference(data):
    frames, results = data
    metrics = evaluate({"meta": {"method": "p"}, "results": results}, {"frames": frames})
    expected = reference_evaluate(results, frames)
    assert metrics["counts"] == expected["counts"]
    for band, ap in expected["ap"].items():
        if ap is None:
            assert metrics["ap"][band] is None
        else:
            assert metrics["ap"][band] == pytest.approx(ap, abs=1e-9)


@settings(max_examples=100, deadline=None)
@given(scenes(), st.randoms(use_true_random=False))
def test_frame_order_and_prediction_order_do_not_change_results(data, rng):
    # Frames in another order (differently in each file), and each frame's predictions re-listed
    # in score order: the list order among equal scores is the protocol's tie-break, so it is kept
    # (a stable sort), everything else may move.
    frames, results = data
    baseline = evaluate({"results": results}, {"frames": frames})
    pred_order, gt_order = list(results), list(frames)
    rng.shuffle(pred_order)
    rng.shuffle(gt_order)
    reordered = {f: sorted(results[f], key=lambda d: -d["score"]) for f in pred_order}
    again = evaluate({"results": reordered}, {"frames": {f: frames[f] for f in gt_order}})
    assert again["counts"] == baseline["counts"]
    assert again["ap"] == baseline["ap"]
    assert again["pr_curves"] == baseline["pr_curves"]


def test_tied_detections_across_frames_in_any_order_give_identical_output():
    # Tied scores in different frames, one TP and one FP: the PR step is the same whichever
    # frame comes first in the file.
    frames = {"a/1": [{"x": 5.0, "y": 0.0}], "b/1": [{"x": 20.0, "y": 0.0}]}
    results = {"a/1": [{"x": 5.0, "y": 0.0, "score": 0.5}], "b/1": [{"x": -20.0, "y": 0.0, "score": 0.5}]}
    forward = evaluate({"results": results}, {"frames": frames})
    backward = evaluate(
        {"results": dict(reversed(list(results.items())))}, {"frames": dict(reversed(list(frames.items())))}
    )
    assert forward["ap"] == backward["ap"]
    assert forward["pr_curves"] == backward["pr_curves"]
    assert forward["ap"]["all"] == pytest.approx(0.25)  # one step: R 1/2, P 1/2


def test_random_large_input_matches_reference():
    rng = random.Random(7)
    frames, results = {}, {}
    for k in range(300):
        frame_id = f"s{k % 7}/{k}"
        frames[frame_id] = [{"x": rng.uniform(-65, 65), "y": rng.uniform(-65, 65)} for _ in range(rng.randint(0, 8))]
        results[frame_id] = [
            {"x": g["x"] + rng.gauss(0, 1.5), "y": g["y"] + rng.gauss(0, 1.5), "score": round(rng.random(), 2)}
            for g in frames[frame_id]
            if rng.random() < 0.8
        ] + [{"x": rng.uniform(-65, 65), "y": rng.uniform(-65, 65), "score": round(rng.random(), 2)} for _ in range(3)]
    metrics = evaluate({"results": results}, {"frames": frames})
    expected = reference_evaluate(results, frames)
    assert metrics["counts"] == expected["counts"]
    for band in expected["ap"]:
        assert metrics["ap"][band] == pytest.approx(expected["ap"][band], abs=1e-9)


def test_crowded_frames_with_tied_scores_match_reference():
    # More than 32 detections a frame takes the kernel's mergesort path instead of insertion sort.
    rng = random.Random(3)
    frames, results = {}, {}
    for k in range(6):
        frame_id = f"crowd/{k}"
        frames[frame_id] = [{"x": rng.uniform(-20, 20), "y": rng.uniform(-20, 20)} for _ in range(60)]
        results[frame_id] = [
            {"x": rng.uniform(-20, 20), "y": rng.uniform(-20, 20), "score": rng.choice([0.2, 0.5, 0.8])}
            for _ in range(rng.choice([20, 200]))
        ]
    metrics = evaluate({"results": results}, {"frames": frames})
    expected = reference_evaluate(results, frames)
    assert metrics["counts"] == expected["counts"]
    for band in expected["ap"]:
        assert metrics["ap"][band] == pytest.approx(expected["ap"][band], abs=1e-9)
