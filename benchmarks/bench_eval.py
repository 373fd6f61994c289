"""Claim: the evaluator scores 100,000 frames with 1,000,000 predictions in <= 5 s on 2 cores,
>= 20x faster than a plain per-prediction Python loop of the same protocol.

Run: python benchmarks/bench_eval.py [--frames 100000] [--per-frame 10] [--reference-frames 10000]

The plain loop is the simple reference implementation kept in tests/eval/eval_reference.py. It is
timed on the first ``--reference-frames`` frames and extrapolated linearly to the full set (its cost
is a sum over frames), and both implementations' APs are compared on that subset.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.eval.eval_reference import reference_evaluate  # noqa: E402

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
    parser.add_argument("--reference-frames", type=int, default=10_000)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()

    ground_truth, predictions = synthetic(args.frames, args.per_frame)
    n_pred = args.frames * args.per_frame
    n_gt = sum(map(len, ground_truth["frames"].values()))
    print(f"{args.frames:,} frames, {n_pred:,} predictions, {n_gt:,} ground truths")

    evaluate(*synthetic(10, 3)[::-1])  # compile the matching kernel (cached on disk afterwards)

    fast_s, metrics = best_of(args.repeats, lambda: evaluate(predictions, ground_truth))
    check_s, (pred_table, gt_table) = best_of(
        args.repeats,
        lambda: (read_predictions(predictions).table, read_ground_truth_document(ground_truth).table),
    )
    core_s, core_metrics = best_of(args.repeats, lambda: score_tables(pred_table, gt_table))
    assert core_metrics["ap"] == metrics["ap"]

    with tempfile.TemporaryDirectory() as tmp:
        pred_path, gt_path = Path(tmp) / "pred.json", Path(tmp) / "gt.json"
        pred_path.write_text(json.dumps(predictions))
        gt_path.write_text(json.dumps(ground_truth))
        size_mb = pred_path.stat().st_size / 1e6
        files_s, from_files = best_of(args.repeats, lambda: evaluate(pred_path, gt_path))
    assert from_files["ap"] == metrics["ap"]

    subset_ids = list(ground_truth["frames"])[: args.reference_frames]
    sub_gt = {f: ground_truth["frames"][f] for f in subset_ids}
    sub_pred = {f: predictions["results"][f] for f in subset_ids}
    reference_s, expected = best_of(1, lambda: reference_evaluate(sub_pred, sub_gt))
    sub_fast = evaluate({"results": sub_pred}, {"frames": sub_gt})
    agree = all(
        (expected["ap"][b] is None and sub_fast["ap"][b] is None)
        or math.isclose(expected["ap"][b], sub_fast["ap"][b], abs_tol=1e-9)
        for b in expected["ap"]
    ) and expected["counts"] == sub_fast["counts"]
    scale = args.frames / len(subset_ids)
    reference_full_s = reference_s * scale

    print()
    print(f"{'implementation':<52} {'time [s]':>9} {'speed-up':>9}")
    print("-" * 72)
    note = f" (timed on {len(subset_ids):,} frames, x{scale:g})" if scale != 1 else ""
    print(f"{'plain per-prediction Python loop' + note:<52} {reference_full_s:>9.2f} {1.0:>8.1f}x")
    print(f"{'scoring core (matching, bands, AP) on checked arrays':<52} {core_s:>9.2f} {reference_full_s / core_s:>8.1f}x")
    print(f"{'checking + reading the dicts into arrays':<52} {check_s:>9.2f} {'':>9}")
    print(f"{'zendar_dataset.eval.evaluate, loaded dicts (all)':<52} {fast_s:>9.2f} {reference_full_s / fast_s:>8.1f}x")
    print(
        f"{f'zendar_dataset.eval.evaluate, JSON files ({size_mb:.0f} MB)':<52} {files_s:>9.2f} "
        f"{reference_full_s / files_s:>8.1f}x"
    )
    print()
    print(f"AP [%] near/mid/far/all: " + " / ".join(f"{100 * metrics['ap'][b]:.2f}" for b in metrics["ap"]))
    print(f"reference and package agree on the {len(subset_ids):,}-frame subset (AP to 1e-9, counts): {agree}")

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
