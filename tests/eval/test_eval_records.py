"""The typed records of metrics.json: exact round trips, unchanged bytes, and every problem named."""

from __future__ import annotations

import json

import pytest

from zendar_dataset.atomic_files import json_text
from zendar_dataset.cli.eval import main as eval_main
from zendar_dataset.errors import ZendarError
from zendar_dataset.eval import (
    ALL_BAND,
    BAND_NAMES,
    BANDS_M,
    RANGE_BANDS,
    BandCounts,
    BootstrapInterval,
    MetricsRecord,
    PRCurve,
    evaluate,
    evaluate_record,
    protocol_dict,
)
from zendar_dataset.eval.report import format_table, read_metrics, write_metrics
from tests.eval.test_eval_cli import scenes_data


def _evaluations():
    ground_truth, predictions = scenes_data()
    first = dict(list(predictions["results"].items())[:10])
    one_frame_gt = {"frames": {"s/1": [{"x": 10.0, "y": 0.0}]}}
    one_frame = {"meta": {"method": "demo", "extra": [1, {"a": None}]},
                 "results": {"s/1": [{"x": 11.0, "y": 0.0, "score": 0.9}]}}
    return {
        "plain": (predictions, ground_truth, {}),
        "bootstrap": (predictions, ground_truth, {"bootstrap": 20, "seed": 3}),
        "partial": ({"results": first}, ground_truth, {"partial": True}),
        "partial_bootstrap": ({"meta": {}, "results": first}, ground_truth, {"partial": True, "bootstrap": 10}),
        "no_split_empty_bands": (one_frame, one_frame_gt, {"bootstrap": 5}),
    }


@pytest.mark.parametrize("case", list(_evaluations()))
def test_round_trip_of_the_evaluators_output_is_exact(case):
    predictions, ground_truth, options = _evaluations()[case]
    metrics = evaluate(predictions, ground_truth, **options)
    record = MetricsRecord.from_json(metrics)
    assert record.to_json() == metrics
    assert json_text(record.to_json()) == json_text(metrics)  # same keys in the same order
    assert evaluate_record(predictions, ground_truth, **options) == record
    assert (record.bootstrap is not None) == ("bootstrap" in options)
    assert record.partial is options.get("partial", False)
    assert (record.split is None) == ("split" not in metrics)
    assert MetricsRecord.from_json(json.loads(json_text(metrics))) == record


def test_metrics_json_bytes_are_the_documented_structure(tmp_path):
    predictions = {"meta": {"method": "demo"}, "results": {"s/1": [{"x": 11.0, "y": 0.0, "score": 0.9}]}}
    ground_truth = {"frames": {"s/1": [{"x": 10.0, "y": 0.0}]}, "split": "test"}
    empty_curve = {"recall": [], "precision": [], "precision_envelope": [], "score": []}
    hit_curve = {"recall": [1.0], "precision": [1.0], "precision_envelope": [1.0], "score": [0.9]}
    expected = {
        "ap": {"near": 1.0, "mid": None, "far": None, "all": 1.0},
        "counts": {
            "near": {"gt": 1, "tp": 1, "fp": 0},
            "mid": {"gt": 0, "tp": 0, "fp": 0},
            "far": {"gt": 0, "tp": 0, "fp": 0},
            "all": {"gt": 1, "tp": 1, "fp": 0},
        },
        "pr_curves": {"near": hit_curve, "mid": empty_curve, "far": empty_curve, "all": hit_curve},
        "protocol": protocol_dict(),
        "partial": False,
        "n_frames": 1,
        "n_frames_ground_truth": 1,
        "n_scenes": 1,
        "n_predictions": 1,
        "bootstrap": {
            "near": {"low": 1.0, "high": 1.0, "n": 4},
            "mid": {"low": None, "high": None, "n": 0},
            "far": {"low": None, "high": None, "n": 0},
            "all": {"low": 1.0, "high": 1.0, "n": 4},
        },
        "split": "test",
        "meta": {"method": "demo"},
    }
    expected_text = json.dumps(expected, indent=1) + "\n"
    pred_path, gt_path = tmp_path / "pred.json", tmp_path / "gt.json"
    pred_path.write_text(json.dumps(predictions))
    gt_path.write_text(json.dumps(ground_truth))
    assert eval_main([str(pred_path), "--gt", str(gt_path), "--bootstrap", "4", "--out", str(tmp_path / "cli")]) == 0
    assert (tmp_path / "cli" / "metrics.json").read_text(encoding="utf-8") == expected_text
    metrics = evaluate(predictions, ground_truth, bootstrap=4)
    assert write_metrics(metrics, tmp_path / "dict").read_text(encoding="utf-8") == expected_text
    record = evaluate_record(predictions, ground_truth, bootstrap=4)
    assert write_metrics(record, tmp_path / "record").read_text(encoding="utf-8") == expected_text
    assert read_metrics(tmp_path / "record" / "metrics.json") == record


def test_records_read_like_the_documented_members():
    predictions, ground_truth, _ = _evaluations()["bootstrap"]
    metrics = evaluate(predictions, ground_truth, bootstrap=20, seed=3)
    record = MetricsRecord.from_json(metrics)
    for band, counts in metrics["counts"].items():
        assert record.counts[band] == BandCounts(**counts)
        assert record.bootstrap[band] == BootstrapInterval(**metrics["bootstrap"][band])
        assert record.pr_curves[band] == PRCurve(**{k: tuple(v) for k, v in metrics["pr_curves"][band].items()})
        assert record.ap[band] == metrics["ap"][band]
    assert record.meta == predictions["meta"] and record.protocol == metrics["protocol"]
    assert format_table(record) == format_table(metrics)
    # to_json hands out copies: changing them leaves the record as it was.
    document = record.to_json()
    document["meta"]["method"] = "changed"
    document["protocol"]["name"] = "changed"
    assert record.to_json() == metrics


def test_band_names_come_from_the_protocol():
    assert BAND_NAMES == tuple(BANDS_M) == (*RANGE_BANDS, ALL_BAND)
    assert ALL_BAND == "all" and RANGE_BANDS == ("near", "mid", "far")


def test_pr_curves_may_be_absent():
    predictions, ground_truth, _ = _evaluations()["plain"]
    metrics = evaluate(predictions, ground_truth)
    del metrics["pr_curves"]
    record = MetricsRecord.from_json(metrics)
    assert record.pr_curves is None and record.to_json() == metrics


def test_every_problem_is_named_with_its_source():
    predictions, ground_truth, _ = _evaluations()["bootstrap"]
    metrics = evaluate(predictions, ground_truth, bootstrap=5)
    del metrics["n_scenes"]
    metrics["surprise"] = 1
    del metrics["ap"]["far"]
    metrics["ap"]["very-far"] = 0.5
    metrics["ap"]["near"] = "high"
    metrics["counts"]["mid"]["tp"] = -1
    metrics["counts"]["all"] = {"gt": 1, "tp": True}
    metrics["bootstrap"]["near"]["low"] = None
    metrics["pr_curves"]["far"]["recall"] = metrics["pr_curves"]["far"]["recall"] + [float("nan")]
    metrics["partial"] = "no"
    metrics["meta"] = []
    with pytest.raises(ZendarError) as caught:
        MetricsRecord.from_json(metrics, source="out/metrics.json")
    problems = caught.value.problems
    assert all(problem.startswith("out/metrics.json: metrics") for problem in problems)
    text = "\n".join(problems)
    for expected in (
        "metrics: missing 'n_scenes'",
        "metrics: unexpected 'surprise'",
        "metrics.ap: missing 'far'",
        "metrics.ap: unexpected 'very-far'",
        "metrics.ap.near: expected a finite number or null, found 'high'",
        "metrics.counts.mid.tp: expected an integer 0 or more, found -1",
        "metrics.counts.all: missing 'fp'",
        "metrics.counts.all.tp: expected an integer 0 or more, found True",
        "metrics.bootstrap.near: expected 'low' and 'high' both numbers or both null",
        "metrics.pr_curves.far.recall: expected finite numbers, found nan",
        "metrics.pr_curves.far: expected recall, precision, precision_envelope, score of one length",
        "metrics.partial: expected true or false, found 'no'",
        "metrics.meta: expected an object, found list",
    ):
        assert expected in text, expected
    assert str(caught.value).startswith(f"out/metrics.json: {len(problems)} problems in the evaluator's metrics: ")


def test_component_records_read_alone():
    assert BandCounts.from_json({"gt": 3, "tp": 2, "fp": 1}) == BandCounts(3, 2, 1)
    # A sum of recall steps may land one rounding step above 1: still the evaluator's output.
    assert BootstrapInterval.from_json({"low": 0.5, "high": 1.0000000000000002, "n": 3}).high == 1.0000000000000002
    assert BootstrapInterval.from_json({"low": 0.25, "high": 0.5, "n": 7}).to_json() == {"low": 0.25, "high": 0.5, "n": 7}
    with pytest.raises(ZendarError, match=r"counts: missing 'fp'"):
        BandCounts.from_json({"gt": 3, "tp": 2})
    with pytest.raises(ZendarError, match=r"bootstrap.high: expected a finite number or null, found inf"):
        BootstrapInterval.from_json({"low": 0.1, "high": float("inf"), "n": 7})
    with pytest.raises(ZendarError, match="pr_curve: expected an object, found list"):
        PRCurve.from_json([])
    with pytest.raises(ZendarError, match="metrics: expected an object, found null"):
        MetricsRecord.from_json(None)


def test_read_metrics_names_the_file(tmp_path):
    path = tmp_path / "metrics.json"
    path.write_text("{not json")
    with pytest.raises(ZendarError, match=f"{path}: cannot be read as the evaluator's metrics"):
        read_metrics(path)
    path.write_text(json.dumps({"ap": {}}))
    with pytest.raises(ZendarError) as caught:
        read_metrics(path)
    assert str(caught.value).startswith(f"{path}: 2 problems in the evaluator's metrics: metrics: missing 'counts', ")
    assert caught.value.problems[1] == f"{path}: metrics.ap: missing 'near', 'mid', 'far', 'all'"
