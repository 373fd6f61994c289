"""Hand-worked examples of the protocol; every expected number is derived in the comments."""

import numpy as np
import pytest

from zendar_dataset.eval import evaluate
from zendar_dataset.eval.ap import average_precision
from zendar_dataset.eval.matching import match_frame, match_frames


def pred(x, y, score):
    return {"x": x, "y": y, "score": score}


def gt(x, y):
    return {"x": x, "y": y}


def run(results, frames, **kwargs):
    return evaluate({"meta": {"method": "t"}, "results": results}, {"frames": frames}, **kwargs)


def test_distance_exactly_2_5_m_does_not_match_and_just_below_does():
    # (1.5, 2.0) from the origin of the offset is exactly 2.5 m: strictly-less fails.
    frames = {"s/1": [gt(10.0, 0.0)], "s/2": [gt(10.0, 0.0)]}
    results = {"s/1": [pred(11.5, 2.0, 0.9)], "s/2": [pred(11.5, 1.999, 0.9)]}
    metrics = run(results, frames)
    assert metrics["counts"]["near"] == {"gt": 2, "tp": 1, "fp": 1}
    # Sorted by score: one step at 0.9 with TP=1, FP=1: recall 1/2, precision 1/2 -> AP 0.25.
    assert metrics["ap"]["near"] == pytest.approx(0.25, abs=1e-12)


@pytest.mark.parametrize(
    ("r_m", "band"), [(0.0, "near"), (14.999, "near"), (15.0, "mid"), (29.999, "mid"), (30.0, "far"), (59.999, "far")]
)
def test_band_edges_are_half_open(r_m, band):
    metrics = run({"s/1": [pred(r_m, 0.0, 0.5)]}, {"s/1": [gt(r_m, 0.0)]})
    for name in ("near", "mid", "far"):
        expected = {"gt": 1, "tp": 1, "fp": 0} if name == band else {"gt": 0, "tp": 0, "fp": 0}
        assert metrics["counts"][name] == expected
        assert metrics["ap"][name] == (1.0 if name == band else None)
    assert metrics["counts"]["all"] == {"gt": 1, "tp": 1, "fp": 0}
    assert metrics["ap"]["all"] == 1.0


def test_sixty_metres_is_in_no_band():
    # GT at exactly 60 m matched by a prediction at 59 m: neither TP nor FP, GT counted nowhere.
    # An unmatched prediction at 60 m is no FP either.
    metrics = run({"s/1": [pred(59.0, 0.0, 0.9), pred(0.0, 60.0, 0.8)]}, {"s/1": [gt(60.0, 0.0)]})
    for band in ("near", "mid", "far", "all"):
        assert metrics["counts"][band] == {"gt": 0, "tp": 0, "fp": 0}
        assert metrics["ap"][band] is None


def test_match_beyond_60_m_consumes_the_prediction():
    # The prediction at 58.5 m matches the GT at 60.5 m (2 m away) rather than being an FP in far;
    # the far GT at 56 m (2.5 m away exactly) cannot be matched by it: far has 1 GT, 0 TP, 0 FP.
    metrics = run({"s/1": [pred(58.5, 0.0, 0.9)]}, {"s/1": [gt(60.5, 0.0), gt(56.0, 0.0)]})
    assert metrics["counts"]["far"] == {"gt": 1, "tp": 0, "fp": 0}
    assert metrics["counts"]["all"] == {"gt": 1, "tp": 0, "fp": 0}
    assert metrics["ap"]["far"] == 0.0


def test_tp_counts_in_its_ground_truths_band_across_an_edge():
    # GT at 14 m (near), prediction at 16 m (mid): one TP in near, nothing in mid.
    metrics = run({"s/1": [pred(16.0, 0.0, 0.7)]}, {"s/1": [gt(14.0, 0.0)]})
    assert metrics["counts"]["near"] == {"gt": 1, "tp": 1, "fp": 0}
    assert metrics["counts"]["mid"] == {"gt": 0, "tp": 0, "fp": 0}
    assert metrics["ap"]["near"] == 1.0
    assert metrics["ap"]["mid"] is None


def test_unmatched_prediction_is_fp_in_its_own_band():
    metrics = run({"s/1": [pred(20.0, 0.0, 0.7)]}, {"s/1": [gt(5.0, 0.0)]})
    assert metrics["counts"]["mid"] == {"gt": 0, "tp": 0, "fp": 1}
    assert metrics["counts"]["near"] == {"gt": 1, "tp": 0, "fp": 0}
    assert metrics["ap"]["mid"] is None  # FPs but no GT: AP undefined
    assert metrics["ap"]["near"] == 0.0  # GT but no detections: AP 0


def test_duplicates_on_one_ground_truth():
    # Three predictions on one GT: the highest score is the TP, the two others are FPs.
    # Points: 0.9 -> (R 1, P 1); 0.8 -> (1, 1/2); 0.7 -> (1, 1/3). AP = 1 * 1 = 1.
    metrics = run(
        {"s/1": [pred(10.2, 0, 0.8), pred(10.0, 0, 0.9), pred(9.9, 0, 0.7)]}, {"s/1": [gt(10.0, 0.0)]}
    )
    assert metrics["counts"]["near"] == {"gt": 1, "tp": 1, "fp": 2}
    assert metrics["ap"]["near"] == 1.0
    assert metrics["pr_curves"]["near"]["precision"] == pytest.approx([1.0, 0.5, 1 / 3])
    assert metrics["pr_curves"]["near"]["score"] == [0.9, 0.8, 0.7]


def test_higher_score_takes_the_nearest_even_if_that_leaves_a_miss():
    # GTs at x=10 and x=12. Prediction A (score 0.9) at 11.2 is nearest to 12 (0.8 m) and takes it;
    # prediction B (0.5) at 13.5 is 1.5 m from 12 (taken) and 3.5 m from 10: unmatched.
    matched = match_frame(
        np.array([[11.2, 0.0], [13.5, 0.0]]), np.array([0.9, 0.5]), np.array([[10.0, 0.0], [12.0, 0.0]])
    )
    assert matched.tolist() == [1, -1]


def test_equal_scores_keep_list_order_and_equal_distances_take_the_earlier_gt():
    # Two predictions with equal score at the same spot between two GTs at equal distance:
    # the first in the list takes the earlier GT, the second takes the other.
    pred_xy = np.array([[10.0, 0.0], [10.0, 0.0]])
    gt_xy = np.array([[10.0, 1.0], [10.0, -1.0]])
    assert match_frame(pred_xy, np.array([0.5, 0.5]), gt_xy).tolist() == [0, 1]
    # One GT only: the first of the tied predictions wins it.
    assert match_frame(pred_xy, np.array([0.5, 0.5]), gt_xy[1:]).tolist() == [0, -1]


def test_vectorised_matching_agrees_with_the_readable_rule_on_ties():
    # Prediction frame 0 is ground-truth frame 1 and vice versa.
    pred_x = np.array([30.0, 30.0, 10.0, 10.0])
    pred_y = np.array([0.0, 0.0, 0.0, 0.0])
    score = np.array([0.1, 0.2, 0.5, 0.5])
    gt_x = np.array([10.0, 10.0, 31.0])
    gt_y = np.array([1.0, -1.0, 0.0])
    matched = match_frames(
        pred_x, pred_y, score, np.array([0, 2, 4]), np.array([1, 0]), gt_x, gt_y, np.array([0, 2, 3])
    )
    assert matched.tolist() == [-1, 2, 0, 1]


def test_empty_frames_and_no_detections():
    metrics = run({"s/1": [], "s/2": []}, {"s/1": [gt(5.0, 0.0)], "s/2": []})
    assert metrics["counts"]["near"] == {"gt": 1, "tp": 0, "fp": 0}
    assert metrics["ap"]["near"] == 0.0
    assert metrics["ap"]["mid"] is None
    assert metrics["n_frames"] == 2


def test_tied_scores_form_one_step():
    # Two detections tied at 0.8, one TP and one FP, 2 GT: one point (R 1/2, P 1/2) -> AP 0.25,
    # whatever their order. Splitting the tie would give 0.5 (TP first) or 0.25 (FP first).
    frames = {"s/1": [gt(5.0, 0.0), gt(8.0, 5.0)]}
    for detections in ([pred(5.0, 0, 0.8), pred(-5.0, 0, 0.8)], [pred(-5.0, 0, 0.8), pred(5.0, 0, 0.8)]):
        assert run({"s/1": detections}, frames)["ap"]["near"] == pytest.approx(0.25, abs=1e-12)


def test_precision_envelope():
    # Scores 0.9 TP, 0.8 FP, 0.7 TP, 0.6 FP, 0.5 TP over 4 GT:
    # points (R, P): (1/4, 1), (1/4, 1/2), (2/4, 2/3), (2/4, 2/4), (3/4, 3/5)
    # envelope: 1, 2/3, 2/3, 3/5, 3/5 -> AP = 1/4*1 + 0 + 1/4*2/3 + 0 + 1/4*3/5
    ap, curve = average_precision(
        np.array([0.9, 0.8, 0.7, 0.6, 0.5]), np.array([True, False, True, False, True]), 4
    )
    assert ap == pytest.approx(0.25 + 0.25 * 2 / 3 + 0.25 * 0.6, abs=1e-12)
    assert curve.precision_envelope.tolist() == pytest.approx([1.0, 2 / 3, 2 / 3, 0.6, 0.6])


def test_band_without_ground_truth_is_null_in_json():
    metrics = run({"s/1": [pred(40.0, 0, 0.9)]}, {"s/1": [gt(5.0, 0.0)]})
    assert metrics["ap"] == {"near": 0.0, "mid": None, "far": None, "all": 0.0}


def test_metrics_structure_and_protocol():
    metrics = run({"s/1": [pred(5.0, 0, 0.9)]}, {"s/1": [gt(5.0, 0.0)]})
    assert set(metrics["ap"]) == {"near", "mid", "far", "all"}
    for band in metrics["ap"]:
        assert set(metrics["counts"][band]) == {"gt", "tp", "fp"}
        assert {"recall", "precision", "score"} <= set(metrics["pr_curves"][band])
    protocol = metrics["protocol"]
    assert protocol["match_distance_m"] == 2.5
    assert protocol["bands_m"] == {"near": [0, 15], "mid": [15, 30], "far": [30, 60], "all": [0, 60]}
    assert protocol["max_detections_per_frame"] == 500
    assert isinstance(protocol["evaluator_version"], str)
    assert metrics["partial"] is False
    assert metrics["meta"] == {"method": "t"}
    assert "split" not in metrics  # unknown for a dict without "split"


def test_many_frames_ap_matches_closed_form():
    # 10 frames, each with one GT at 10 m; frame k has a TP with score k/10 and, in odd frames, an FP
    # with score k/10 + 0.05. Walk down the ranking by hand:
    scores_tp = [k / 10 for k in range(10)]
    frames = {f"s/{k}": [gt(10.0, 0.0)] for k in range(10)}
    results = {
        f"s/{k}": [pred(10.0, 0.0, k / 10)] + ([pred(-10.0, 0.0, k / 10 + 0.05)] if k % 2 else [])
        for k in range(10)
    }
    entries = sorted(
        [(s, True) for s in scores_tp] + [(k / 10 + 0.05, False) for k in range(1, 10, 2)], key=lambda e: -e[0]
    )
    tp = fp = 0
    points = []
    for _, is_tp in entries:
        tp += is_tp
        fp += not is_tp
        points.append((tp / 10, tp / (tp + fp)))
    expected = 0.0
    previous = 0.0
    for n, (recall, _) in enumerate(points):
        expected += (recall - previous) * max(p for _, p in points[n:])
        previous = recall
    assert run(results, frames)["ap"]["near"] == pytest.approx(expected, abs=1e-12)
