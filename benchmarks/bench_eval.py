"""Claim: the evaluator scores 100,000 frames with 1,000,000 predictions in <= 5 s on 2 cores,
>= 20x faster than a plain per-prediction Python loop of the same protocol.

Run: python benchmarks/bench_eval.py [--frames 100000] [--per-frame 10] [--repeats 3]

The plain loop is the reference implementation kept in tests/eval/eval_reference.py, run on the
full set in this same process. Both start from the same loaded dicts, and both are split in two
parts: reading the dicts into their working form (plain: tuples per frame, no checks; package:
every value checked, then flat float64 columns) and scoring (matching, bands, AP). Each step of one
alternates with the same step of the other (best of --repeats each), so that both see the same
machine load; CPU-time ratios are printed beside the wall-time ones. The >= 20x
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
    """(best wall time [s], best CPU time [s], value) over ``repeats`` calls."""
    wall, cpu = [], []
    for _ in range(repeats):
        start_wall, start_cpu = time.perf_counter(), time.process_time()
        value = function()
        wall.append(time.perf_counter() - start_wall)
        cpu.append(time.process_time() - start_cpu)
    return min(wall), min(cpu), value


def side_by_side(repeats: int, plain, package):
    """Alternate the two ``repeats`` times, so that both see the same machine load.

    Returns ((wall, cpu) of plain, (wall, cpu) of package, plain's value, package's value).
    """
    plain_runs, package_runs = [], []
    for _ in range(repeats):
        plain_runs.append(best_of(1, plain))
        package_runs.append(best_of(1, package))
    best = lambda runs: (min(r[0] for r in runs), min(r[1] for r in runs))  # noqa: E731
    return best(plain_runs), best(package_runs), plain_runs[-1][2], package_runs[-1][2]


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

    # Each step of the plain loop alternates with the same step of the package.
    pred_dicts, gt_dicts = predictions["results"], ground_truth["frames"]
    plain_read, check, tables, (pred_table, gt_table) = side_by_side(
        args.repeats,
        lambda: reference_tables(pred_dicts, gt_dicts),
        lambda: (read_predictions(predictions).table, read_ground_truth_document(ground_truth).table),
    )
    plain_score, core, expected, core_metrics = side_by_side(
        args.repeats, lambda: reference_score(tables), lambda: score_tables(pred_table, gt_table)
    )
    del tables
    plain_all, fast, _, metrics = side_by_side(
        args.repeats,
        lambda: reference_score(reference_tables(pred_dicts, gt_dicts)),
        lambda: evaluate(predictions, ground_truth),
    )
    assert core_metrics["ap"] == metrics["ap"]

    with tempfile.TemporaryDirectory() as tmp:
        pred_path, gt_path = Path(tmp) / "pred.json", Path(tmp) / "gt.json"
        pred_path.write_bytes(orjson.dumps(predictions))
        gt_path.write_bytes(orjson.dumps(ground_truth))
        size_mb = (pred_path.stat().st_size + gt_path.stat().st_size) / 1e6

        def plain_from_files():
            results = orjson.loads(pred_path.read_bytes())["results"]
            return reference_score(reference_tables(results, orjson.loads(gt_path.read_bytes())["frames"]))

        plain_files, files, _, from_files = side_by_side(
            args.repeats, plain_from_files, lambda: evaluate(pred_path, gt_path)
        )
    assert from_files["ap"] == metrics["ap"]

    agree = all(
        (expected["ap"][b] is None and metrics["ap"][b] is None)
        or math.isclose(expected["ap"][b], metrics["ap"][b], abs_tol=1e-9)
        for b in expected["ap"]
    ) and expected["counts"] == metrics["counts"]

    rows = [
        ("scoring: matching, bands, AP  <- the >= 20x target", plain_score, core),
        ("reading the dicts (package: checks every value)", plain_read, check),
        ("(a) end to end from loaded dicts", plain_all, fast),
        (f"(c) end to end from JSON files ({size_mb:.0f} MB, orjson)", plain_files, files),
    ]
    print()
    print(f"{'step':<54} {'plain loop [s]':>15} {'package [s]':>12} {'speed-up':>9} {'CPU time':>9}")
    print(f"{'':<54} {'wall':>15} {'wall':>12} {'(wall)':>9} {'speed-up':>9}")
    print("-" * 103)
    for label, (plain_wall, plain_cpu), (package_wall, package_cpu) in rows:
        print(
            f"{label:<54} {plain_wall:>15.2f} {package_wall:>12.2f} {plain_wall / package_wall:>8.1f}x "
            f"{plain_cpu / package_cpu:>8.1f}x"
        )
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
