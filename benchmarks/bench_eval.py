"""Claim: the evaluator scores 100,000 frames with 1,000,000 predictions in <= 5 s on 2 cores,
>= 20x faster than a plain per-prediction Python loop of the same protocol.

Run: python benchmarks/bench_eval.py [--frames 100000] [--per-frame 10] [--repeats 3]

The plain loop is the reference implementation kept in tests/eval/eval_reference.py, run on the
full set in this same process. Both start from the same loaded dicts, and both are split in two
parts: reading the dicts into their working form (plain: tuples per frame, no checks; package:
every value checked, then flat float64 columns) and scoring (matching, bands, AP). The >= 20x
target is the scoring ratio ("scored ... faster than a plain loop"); end-to-end ratios, from
loaded dicts and from JSON files (both parsed with orjson), are printed beside it.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np
import orjson

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.eval.eval_reference import reference_score, reference_tables  # noqa: E402

from zendar_dataset.eval import evaluate  # noqa: E402
from zendar_dataset.eval.evaluate import score_tables  # noqa: E402
from zendar_dataset.eval.validation import read_ground_truth_document, read_predictions  # noqa: E402


def synthetic(n_frames: int, per_frame: int, seed: int = 0) -> tuple[dict, dict]:
    """Ground truth (about 3 cars a frame) and ``per_frame`` predictions a frame: noisy hits + clutter."""
    rng = np.random.default_rng(seed)
    n_cars = rng.integers(0, 7, n_frames)
    frames, results = {}, {}
    car_xy = rng.uniform(-70, 70, (int(n_cars.sum()), 2)).tolist()
    noise = rng.normal(0, 1.5, (n_frames * per_frame, 2)).tolist()
    clutter = rng.uniform(-70, 70, (n_frames * per_frame, 2)).tolist()
    scores = np.round(rng.random(n_frames * per_frame), 3).tolist()  # rounded: many tied scores
    car = 0
    p = 0
    for f in range(n_frames):
        frame_id = f"scene-{f // 200:04d}/{1_600_000_000_000_000_000 + f * 100_000_000}"
        cars = car_xy[car : car + n_cars[f]]
        car += n_cars[f]
        frames[frame_id] = [{"x": x, "y": y} for x, y in cars]
        detections = []
        for k in range(per_frame):
            if k < len(cars):
                x, y = cars[k][0] + noise[p][0], cars[k][1] + noise[p][1]
            else:
                x, y = clutter[p]
            detections.append({"x": x, "y": y, "score": scores[p]})
            p += 1
        results[frame_id] = detections
    return {"frames": frames}, {"meta": {"method": "synthetic"}, "results": results}


def best_of(repeats: int, function):
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        value = function()
        times.append(time.perf_counter() - start)
    return min(times), value


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=100_000)
    parser.add_argument("--per-frame", type=int, default=10)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()

    ground_truth, predictions = synthetic(args.frames, args.per_frame)
    n_pred = args.frames * args.per_frame
    n_gt = sum(map(len, ground_truth["frames"].values()))
    print(f"{args.frames:,} frames, {n_pred:,} predictions, {n_gt:,} ground truths")
    print(f"load average before timing (1, 5, 15 min): {', '.join(f'{x:.2f}' for x in os.getloadavg())}")

    evaluate(*synthetic(10, 3)[::-1])  # compile the kernels (cached on disk afterwards)

    # The plain loop, in its two parts and whole.
    plain_read_s, tables = best_of(
        args.repeats, lambda: reference_tables(predictions["results"], ground_truth["frames"])
    )
    plain_score_s, expected = best_of(args.repeats, lambda: reference_score(tables))
    del tables
    plain_s = plain_read_s + plain_score_s

    # The package, in its two parts and whole.
    check_s, (pred_table, gt_table) = best_of(
        args.repeats,
        lambda: (read_predictions(predictions).table, read_ground_truth_document(ground_truth).table),
    )
    core_s, core_metrics = best_of(args.repeats, lambda: score_tables(pred_table, gt_table))
    fast_s, metrics = best_of(args.repeats, lambda: evaluate(predictions, ground_truth))
    assert core_metrics["ap"] == metrics["ap"]

    with tempfile.TemporaryDirectory() as tmp:
        pred_path, gt_path = Path(tmp) / "pred.json", Path(tmp) / "gt.json"
        pred_path.write_bytes(orjson.dumps(predictions))
        gt_path.write_bytes(orjson.dumps(ground_truth))
        size_mb = (pred_path.stat().st_size + gt_path.stat().st_size) / 1e6
        files_s, from_files = best_of(args.repeats, lambda: evaluate(pred_path, gt_path))
        parse_s, _ = best_of(
            args.repeats, lambda: (orjson.loads(pred_path.read_bytes()), orjson.loads(gt_path.read_bytes()))
        )
    assert from_files["ap"] == metrics["ap"]
    plain_files_s = parse_s + plain_s

    agree = all(
        (expected["ap"][b] is None and metrics["ap"][b] is None)
        or math.isclose(expected["ap"][b], metrics["ap"][b], abs_tol=1e-9)
        for b in expected["ap"]
    ) and expected["counts"] == metrics["counts"]

    rows = [
        ("scoring: matching, bands, AP  <- the >= 20x target", plain_score_s, core_s),
        ("reading the dicts (package: checks every value)", plain_read_s, check_s),
        ("(a) end to end from loaded dicts", plain_s, fast_s),
        (f"(c) end to end from JSON files ({size_mb:.0f} MB, orjson)", plain_files_s, files_s),
    ]
    print()
    print(f"{'step':<56} {'plain loop [s]':>15} {'package [s]':>12} {'speed-up':>9}")
    print("-" * 95)
    for label, plain_time, package_time in rows:
        print(f"{label:<56} {plain_time:>15.2f} {package_time:>12.2f} {plain_time / package_time:>8.1f}x")
    print()
    print("AP [%] near/mid/far/all: " + " / ".join(f"{100 * metrics['ap'][b]:.2f}" for b in metrics["ap"]))
    print(f"plain loop and package agree on all {args.frames:,} frames (AP to 1e-9, counts): {agree}")

    # Memory: peak of Python allocations during scoring, at one tenth and at the full size.
    print()
    print(f"{'predictions':>12} {'peak allocated [MB]':>20} {'bytes per prediction':>21}")
    tenth = args.frames // 10
    small_gt = {"frames": dict(list(ground_truth["frames"].items())[:tenth])}
    small_pred = {"results": dict(list(predictions["results"].items())[:tenth])}
    for label, (p, g) in ((tenth * args.per_frame, (small_pred, small_gt)), (n_pred, (predictions, ground_truth))):
        tracemalloc.start()
        evaluate(p, g)
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        print(f"{label:>12,} {peak / 1e6:>20.1f} {peak / label:>21.0f}")


if __name__ == "__main__":
    main()
