"""A deliberately plain implementation of the evaluation protocol, written from docs/evaluation.md.

Plain Python loops over lists; it shares no code with zendar_dataset.eval so that the two can be
checked against each other. It is also the baseline of benchmarks/bench_eval.py, so it is plain
but not careless: reading the dicts (:func:`reference_tables`) is kept apart from scoring
(:func:`reference_score`), and the precision envelope is one backward pass.
"""

from __future__ import annotations

import math

MATCH_DISTANCE_M = 2.5
BANDS = {"near": (0.0, 15.0), "mid": (15.0, 30.0), "far": (30.0, 60.0), "all": (0.0, 60.0)}


def band_contains(band, r):
    low, high = BANDS[band]
    return low <= r < high


def match_one_frame(predictions, ground_truths):
    """predictions: [(x, y, score)], ground_truths: [(x, y)].

    Return, for each prediction (list order), the index of its ground truth or None.
    """
    order = sorted(range(len(predictions)), key=lambda i: -predictions[i][2])  # sorted is stable
    taken = [False] * len(ground_truths)
    result = [None] * len(predictions)
    for i in order:
        best = None
        best_distance = None
        for j, gt in enumerate(ground_truths):
            if taken[j]:
                continue
            dx = predictions[i][0] - gt[0]
            dy = predictions[i][1] - gt[1]
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
    envelope = [0.0] * len(points)  # max precision over this and all later points
    running = 0.0
    for n in range(len(points) - 1, -1, -1):
        running = max(running, points[n][1])
        envelope[n] = running
    ap = 0.0
    previous_recall = 0.0
    for n, (recall, _) in enumerate(points):
        ap += (recall - previous_recall) * envelope[n]
        previous_recall = recall
    return ap


def reference_tables(results, frames):
    """Read the dicts: per ground-truth frame, ([(x, y, score)], [(x, y)])."""
    tables = []
    for frame_id, ground_truths in frames.items():
        predictions = [(d["x"], d["y"], d["score"]) for d in results[frame_id]]
        tables.append((predictions, [(gt["x"], gt["y"]) for gt in ground_truths]))
    return tables


def reference_score(tables):
    """Score the output of :func:`reference_tables`.

    Returns {"ap": {band: float | None}, "counts": {band: {"gt", "tp", "fp"}}}.
    """
    entries = {band: [] for band in BANDS}
    counts = {band: {"gt": 0, "tp": 0, "fp": 0} for band in BANDS}
    for predictions, ground_truths in tables:
        for x, y in ground_truths:
            r = math.sqrt(x * x + y * y)
            for band in BANDS:
                if band_contains(band, r):
                    counts[band]["gt"] += 1
        matches = match_one_frame(predictions, ground_truths)
        for prediction, match in zip(predictions, matches):
            if match is None:
                x, y = prediction[0], prediction[1]
                kind = "fp"
            else:
                x, y = ground_truths[match]
                kind = "tp"
            r = math.sqrt(x * x + y * y)
            for band in BANDS:
                if band_contains(band, r):
                    counts[band][kind] += 1
                    entries[band].append((prediction[2], kind == "tp"))
    ap = {band: reference_ap(entries[band], counts[band]["gt"]) for band in BANDS}
    return {"ap": ap, "counts": counts}


def reference_evaluate(results, frames):
    """results: {frame_id: [pred dicts]}, frames: {frame_id: [gt dicts]} over the same frame ids.

    Returns {"ap": {band: float | None}, "counts": {band: {"gt", "tp", "fp"}}}.
    """
    return reference_score(reference_tables(results, frames))
