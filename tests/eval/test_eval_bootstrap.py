"""Scene resampling: a resample's weights must score like a file with the scenes duplicated."""

import random

import numpy as np
import pytest

from zendar_dataset.eval import evaluate
from zendar_dataset.eval.ap import sort_by_score
from zendar_dataset.eval.bootstrap import BandDetections, bootstrap_intervals, weighted_average_precision
from zendar_dataset.eval.matching import match_frames
from zendar_dataset.eval.protocol import BANDS_M, in_band, range_m
from zendar_dataset.eval.validation import read_frames


def two_scenes(seed=5):
    rng = random.Random(seed)
    frames, results = {}, {}
    for scene in ("a", "b"):
        for t in range(5):
            cars = [{"x": rng.uniform(-50, 50), "y": rng.uniform(-50, 50)} for _ in range(4)]
            frames[f"{scene}/{t}"] = cars
            results[f"{scene}/{t}"] = [
                {"x": c["x"] + rng.gauss(0, 1.5), "y": c["y"], "score": round(rng.random(), 1)} for c in cars
            ] + [{"x": rng.uniform(-50, 50), "y": 3.0, "score": round(rng.random(), 1)}]
    return frames, results


def band_detections(frames, results):
    gt = read_frames(frames, who="gt", required=("x", "y")).table
    pred = read_frames(results, who="p", required=("x", "y", "score")).table
    frame_of = pred.frame_of_row
    assert pred.frame_ids == gt.frame_ids
    same_frame = np.arange(len(pred.frame_ids))
    matched = match_frames(pred.x_m, pred.y_m, pred.score, pred.offsets, same_frame, gt.x_m, gt.y_m, gt.offsets)
    is_tp = matched >= 0
    gt_r = range_m(gt.x_m, gt.y_m)
    det_r = range_m(pred.x_m, pred.y_m)
    det_r[is_tp] = gt_r[matched[is_tp]]
    frame_scene = np.array([0 if f.startswith("a/") else 1 for f in pred.frame_ids])
    gt_scene = np.repeat(frame_scene, gt.counts)
    return {
        band: BandDetections(
            pred.score[in_band(det_r, band)],
            is_tp[in_band(det_r, band)],
            frame_scene[frame_of][in_band(det_r, band)],
            gt_scene[in_band(gt_r, band)],
        )
        for band in BANDS_M
    }


@pytest.mark.parametrize("weights", [(3, 1), (0, 2), (1, 1), (2, 0)])
def test_weights_equal_duplicated_scenes(weights):
    frames, results = two_scenes()
    dup_frames, dup_results = {}, {}
    for frame_id in frames:
        for copy in range(weights[0 if frame_id.startswith("a/") else 1]):
            dup_frames[f"{copy}-{frame_id}"] = frames[frame_id]
            dup_results[f"{copy}-{frame_id}"] = results[frame_id]
    duplicated = evaluate({"results": dup_results}, {"frames": dup_frames})
    for band, detections in band_detections(frames, results).items():
        order, ends = sort_by_score(detections.score)
        weighted = weighted_average_precision(detections, np.array(weights), order, ends)
        if duplicated["ap"][band] is None:
            assert np.isnan(weighted)
        else:
            assert weighted == pytest.approx(duplicated["ap"][band], abs=1e-12)


def test_intervals_contain_the_point_estimate_and_narrow_with_more_scenes():
    rng = random.Random(11)
    frames, results = {}, {}
    for s in range(40):
        for t in range(3):
            cars = [{"x": rng.uniform(0, 14), "y": rng.uniform(-2, 2)} for _ in range(2)]
            frames[f"s{s}/{t}"] = cars
            results[f"s{s}/{t}"] = [
                {"x": c["x"] + rng.gauss(0, 1.5), "y": c["y"], "score": rng.random()} for c in cars
            ] + [{"x": rng.uniform(0, 14), "y": 10.0, "score": rng.random()}]
    metrics = evaluate({"results": results}, {"frames": frames}, bootstrap=300)
    near = metrics["bootstrap"]["near"]
    assert near["n"] == 300
    assert near["low"] < metrics["ap"]["near"] < near["high"]
    few = evaluate(
        {"results": {f: v for f, v in results.items() if int(f[1:].split("/")[0]) < 5}},
        {"frames": {f: v for f, v in frames.items() if int(f[1:].split("/")[0]) < 5}},
        bootstrap=300,
    )["bootstrap"]["near"]
    assert (few["high"] - few["low"]) > (near["high"] - near["low"])
    assert metrics["bootstrap"]["mid"] == {"low": None, "high": None, "n": 0}


def test_no_scenes():
    empty = BandDetections(np.zeros(0), np.zeros(0, bool), np.zeros(0, np.int64), np.zeros(0, np.int64))
    assert bootstrap_intervals({"near": empty}, 0, 10) == {"near": {"low": None, "high": None, "n": 0}}
