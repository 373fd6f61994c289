"""A deliberately plain implementation of the evaluation protocol, written from docs/evaluation.md.

Plain Python loops over dicts; it shares no code with zendar_dataset.eval so that the two can be
checked against each other.
"""

from __future__ import annotations

import math

MATCH_DISTANCE_M = 2.5
BANDS = {"near": (0.0, 15.0), "mid": (15.0, 30.0), "far": (30.0, 60.0), "all": (0.0, 60.0)}


def band_contains(band, r):
    low, high = BANDS[band]
    return low <= r < high


def match_one_frame(predictions, ground_truths):
    """Return, for each prediction (list order), the index of its ground truth or None."""
    order = sorted(range(len(predictions)), key=lambda i: -predictions[i]["score"])  # sorted is stable
    taken = [False] * len(ground_truths)
    result = [None] * len(predictions)
    for i in order:
        best = None
        best_distance = None
        for j, gt in enumerate(ground_truths):
            if taken[j]:
                continue
            dx = predictions[i]["x"] - gt["x"]
            dy = predictions[i]["y"] - gt["y"]
            distance = math.sqrt(dx * dx + dy * dy)
            if distance >= MATCH_DISTANCE_M:
                continue
            if best is None or distance < best_distance:
                best = j
                best_distance = distance
        if best is not None:
            taken[best] = True
            result[i] = best
    return result


def reference_ap(entries, n_gt):
    """entries: list of (score, is_tp). Ties in score form one step."""
    if n_gt == 0:
        return None
    entries = sorted(entries, key=lambda e: -e[0])
    points = []  # (recall, precision) after each distinct score
    tp = fp = 0
    k = 0
    while k < len(entries):
        score = entries[k][0]
        while k < len(entries) and entries[k][0] == score:
            if entries[k][1]:
                tp += 1
            else:
                fp += 1
            k += 1
        points.append((tp / n_gt, tp / (tp + fp)))
    ap = 0.0
    previous_recall = 0.0
    for n, (recall, _) in enumerate(points):
        envelope = max(p for _, p in points[n:])
        ap += (recall - previous_recall) * envelope
        previous_recall = recall
    return ap


def reference_evaluate(results, frames):
    """results: {frame_id: [pred dicts]}, frames: {frame_id: [gt dicts]} over the same frame ids.

    Returns {"ap": {band: float | None}, "counts": {band: {"gt", "tp", "fp"}}}.
    """
    entries = {band: [] for band in BANDS}
    counts = {band: {"gt": 0, "tp": 0, "fp": 0} for band in BANDS}
    for frame_id, ground_truths in frames.items():
        predictions = results[frame_id]
        for gt in ground_truths:
            r = math.sqrt(gt["x"] * gt["x"] + gt["y"] * gt["y"])
            for band in BANDS:
                if band_contains(band, r):
                    counts[band]["gt"] += 1
        matches = match_one_frame(predictions, ground_truths)
        for prediction, match in zip(predictions, matches):
            if match is None:
                where = prediction
                kind = "fp"
            else:
                where = ground_truths[match]
                kind = "tp"
            r = math.sqrt(where["x"] * where["x"] + where["y"] * where["y"])
            for band in BANDS:
                if band_contains(band, r):
                    counts[band][kind] += 1
                    entries[band].append((prediction["score"], kind == "tp"))
    ap = {band: reference_ap(entries[band], counts[band]["gt"]) for band in BANDS}
    return {"ap": ap, "counts": counts}
