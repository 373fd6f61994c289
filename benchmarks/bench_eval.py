"""Claim: the evaluator scores 100,000 frames with 1,000,000 predictions in <= 5 s on 2 cores,
>= 20x faster than a plain per-prediction Python loop of the same protocol.

Run: python benchmarks/bench_eval.py [--frames 100000] [--per-frame 10] [--repeats 3]
                                     [--nuscenes-frames 20000] [--skip-memory]

1. Plain loop (same protocol): the reference implementation kept in tests/eval/eval_reference.py
   (plain Python per frame, written from docs/evaluation.md; matching is sequential within a
   frame, so there is no vectorised numpy form of it). Both start from the same loaded dicts,
   split in two parts: reading the dicts (plain: tuples, no checks; package: every value checked,
   then flat columns) and scoring (matching, bands, AP); end to end from dicts and from JSON files
   (orjson on both sides). Package and plain loop alternate call by call (``--repeats`` each).
2. Peer package: the nuScenes devkit's detection ``accumulate`` (the matching + PR curve of the
   nuScenes detection benchmark: greedy by descending score, center distance < 2.5 m, the same
   rule as this protocol) on the same predictions, every one inside 55 m so that the protocol's
   ``all`` band holds them all, and all scores distinct so that both order predictions alike. TP
   and FP must be identical. Three figures: in process from built boxes (devkit) vs from loaded
   dicts (package); counting the devkit's box construction from the dicts; and end to end from
   the JSON files, each side as a fresh process (``zendar-eval`` CLI vs a script that loads the
   files with ``json`` as the devkit does, builds boxes and accumulates).
3. Memory: peak RSS of the ``zendar-eval`` CLI as a subprocess (parsing included) at three
   sizes; bytes per prediction = the RSS growth between sizes per added prediction.

Threads: everything here is single-threaded (the package's compiled kernels are serial).
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import orjson
from harness import Spread, interleaved, missing_peer, print_environment, print_load_after

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.eval.eval_reference import reference_score, reference_tables  # noqa: E402

from zendar_dataset.eval import ALL_BAND, BAND_NAMES, evaluate, evaluate_record  # noqa: E402
from zendar_dataset.eval.evaluate import score_tables  # noqa: E402
from zendar_dataset.eval.validation import read_ground_truth_document, read_predictions  # noqa: E402


def synthetic(n_frames: int, per_frame: int, seed: int = 0, radius_m: float | None = None) -> tuple[dict, dict]:
    """Ground truth (about 3 cars a frame) and ``per_frame`` predictions a frame: noisy hits + clutter.

    Without ``radius_m``: positions uniform in a 140 m square, scores rounded to 3 decimals (many
    ties). With it: everything inside ``radius_m`` of the ego and all scores distinct.
    """
    rng = np.random.default_rng(seed)
    n_cars = rng.integers(0, 7, n_frames)
    n_pred = n_frames * per_frame

    def positions(n: int) -> list:
        if radius_m is None:
            return rng.uniform(-70, 70, (n, 2)).tolist()
        r = radius_m * np.sqrt(rng.random(n))
        a = rng.uniform(0, 2 * np.pi, n)
        return np.c_[r * np.cos(a), r * np.sin(a)].tolist()

    car_xy = positions(int(n_cars.sum()))
    noise = np.clip(rng.normal(0, 1.5, (n_pred, 2)), -4.0, 4.0).tolist()
    clutter = positions(n_pred)
    if radius_m is None:
        scores = np.round(rng.random(n_pred), 3).tolist()
    else:
        scores = ((rng.permutation(n_pred) + 1) / (n_pred + 1)).tolist()
    frames, results = {}, {}
    car = p = 0
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


# --- 1. plain loop -----------------------------------------------------------------------------


def plain_loop_rows(ground_truth: dict, predictions: dict, repeats: int, workdir: Path) -> list[tuple]:
    pred_dicts, gt_dicts = predictions["results"], ground_truth["frames"]
    tables = reference_tables(pred_dicts, gt_dicts)
    pred_table, gt_table = read_predictions(predictions).table, read_ground_truth_document(ground_truth).table
    expected, metrics = reference_score(tables), evaluate(predictions, ground_truth)
    agree = all(
        (expected["ap"][b] is None and metrics["ap"][b] is None)
        or math.isclose(expected["ap"][b], metrics["ap"][b], abs_tol=1e-9)
        for b in expected["ap"]
    ) and expected["counts"] == metrics["counts"]
    print(f"plain loop and package agree (AP to 1e-9, counts per band): {agree}")
    print(f"AP [%] {'/'.join(BAND_NAMES)}: " + " / ".join(f"{100 * metrics['ap'][b]:.2f}" for b in BAND_NAMES))

    pred_path, gt_path = workdir / "pred.json", workdir / "gt.json"
    pred_path.write_bytes(orjson.dumps(predictions))
    gt_path.write_bytes(orjson.dumps(ground_truth))
    size_mb = (pred_path.stat().st_size + gt_path.stat().st_size) / 1e6

    def plain_from_files() -> dict:
        results = orjson.loads(pred_path.read_bytes())["results"]
        return reference_score(reference_tables(results, orjson.loads(gt_path.read_bytes())["frames"]))

    steps = [
        ("scoring: matching, bands, AP (the >= 20x target)",
         lambda: reference_score(tables), lambda: score_tables(pred_table, gt_table)),
        ("reading the dicts (package: checks every value)",
         lambda: reference_tables(pred_dicts, gt_dicts),
         lambda: (read_predictions(predictions).table, read_ground_truth_document(ground_truth).table)),
        ("end to end from loaded dicts",
         lambda: reference_score(reference_tables(pred_dicts, gt_dicts)), lambda: evaluate(predictions, ground_truth)),
        (f"end to end from JSON files ({size_mb:.0f} MB, orjson)", plain_from_files, lambda: evaluate(pred_path, gt_path)),
    ]
    rows = []
    for label, plain, package in steps:
        t = interleaved({"plain": plain, "package": package}, repeats, warmup=0)
        rows.append((label, t["package"], "plain per-frame Python loop", t["plain"]))
    return rows


# --- 2. nuScenes devkit --------------------------------------------------------------------------


NUSCENES_SCRIPT = """
import json, sys
from nuscenes.eval.common.data_classes import EvalBoxes
from nuscenes.eval.common.utils import center_distance
from nuscenes.eval.detection.algo import accumulate
from nuscenes.eval.detection.data_classes import DetectionBox

def boxes(frames, scored):
    out = EvalBoxes()
    for token, entries in frames.items():
        out.add_boxes(token, [DetectionBox(sample_token=token, translation=(e["x"], e["y"], 0.0), size=(1.9, 4.5, 1.6),
                                           rotation=(1.0, 0.0, 0.0, 0.0), detection_name="car",
                                           detection_score=e["score"] if scored else -1.0) for e in entries])
    return out

def run(pred_frames, gt_frames):
    return accumulate(boxes(gt_frames, False), boxes(pred_frames, True), "car", center_distance, 2.5)

if __name__ == "__main__":
    with open(sys.argv[1]) as f:
        pred = json.load(f)["results"]
    with open(sys.argv[2]) as f:
        gt = json.load(f)["frames"]
    for token in pred:
        gt.setdefault(token, [])
    run(pred, gt)
"""


class _RecordingNumpy:
    """numpy as seen by the devkit's algo module, recording what ``accumulate`` passes to
    ``cumsum`` (its per-prediction TP flags, then FP flags): it returns only interpolated
    curves, and the counts are what must agree."""

    def __init__(self) -> None:
        self.cumsum_inputs: list[list] = []

    def __getattr__(self, name: str):
        return getattr(np, name)

    def cumsum(self, values, *args, **kwargs):
        self.cumsum_inputs.append(list(values))
        return np.cumsum(values, *args, **kwargs)


# Runs the command as its child and prints the child's peak RSS. A process forked from this
# (large) one starts with this one's high-water mark, which exec keeps; a small launcher's child does not.
LAUNCHER = """
import resource, subprocess, sys
code = subprocess.run(sys.argv[1:], stdout=subprocess.DEVNULL).returncode
print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, code)
"""


def wait_rss(command: list[str]) -> tuple[float, int]:
    """Run ``command``; (wall seconds, its peak RSS in bytes)."""
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", LAUNCHER, *command], capture_output=True, text=True)
    seconds = time.perf_counter() - start
    try:
        maxrss_kib, code = (int(v) for v in done.stdout.split()[-2:])
    except ValueError:
        code = -1
    if done.returncode != 0 or code != 0:
        raise RuntimeError(f"{' '.join(command)} failed: {done.stderr[-2000:]}")
    return seconds, maxrss_kib * 1024


def cli_command(pred_path: Path, gt_path: Path, out: Path) -> list[str]:
    return [sys.executable, "-m", "zendar_dataset.cli.eval", str(pred_path), "--gt", str(gt_path), "--out", str(out)]


def nuscenes_rows(n_frames: int, per_frame: int, repeats: int, workdir: Path) -> list[tuple]:
    try:
        import nuscenes.eval.detection.algo as algo
    except ImportError:
        missing_peer("nuscenes-devkit", "evaluator against the nuScenes devkit's accumulate")
        return []
    namespace: dict = {}
    exec(compile(NUSCENES_SCRIPT, "nuscenes_accumulate", "exec"), namespace)
    ground_truth, predictions = synthetic(n_frames, per_frame, seed=1, radius_m=50.0)
    pred_frames, gt_frames = predictions["results"], ground_truth["frames"]
    n_pred = n_frames * per_frame

    recording = _RecordingNumpy()
    algo.np = recording
    try:
        namespace["run"](pred_frames, gt_frames)
    finally:
        algo.np = np
    tp, fp = (int(sum(flags)) for flags in recording.cumsum_inputs[:2])
    counts = evaluate_record(predictions, ground_truth).counts[ALL_BAND]
    print(f"nuScenes devkit: {n_pred:,} predictions, {counts.gt:,} ground truths; TP/FP devkit {tp:,}/{fp:,}, "
          f"package {counts.tp:,}/{counts.fp:,}: identical {(tp, fp) == (counts.tp, counts.fp)}")

    gt_boxes, pred_boxes = namespace["boxes"](gt_frames, False), namespace["boxes"](pred_frames, True)
    t = interleaved(
        {
            "package": lambda: evaluate(predictions, ground_truth),
            "accumulate": lambda: algo.accumulate(gt_boxes, pred_boxes, "car", namespace["center_distance"], 2.5),
            "boxes + accumulate": lambda: namespace["run"](pred_frames, gt_frames),
        },
        repeats,
        warmup=0,
    )
    rows = [
        (f"{n_pred // 1000}k predictions, in process (package from dicts)", t["package"],
         "nuScenes accumulate on built boxes", t["accumulate"]),
        ("", t["package"], "nuScenes box construction + accumulate", t["boxes + accumulate"]),
    ]

    pred_path, gt_path = workdir / "ns_pred.json", workdir / "ns_gt.json"
    pred_path.write_text(json.dumps(predictions))
    gt_path.write_text(json.dumps(ground_truth))
    script = workdir / "nuscenes_accumulate.py"
    script.write_text(NUSCENES_SCRIPT)
    cli_times, ns_times = [], []
    for k in range(repeats):
        out = workdir / f"cli-out-{k}"
        cli_times.append(wait_rss(cli_command(pred_path, gt_path, out))[0])
        shutil.rmtree(out)
        ns_times.append(wait_rss([sys.executable, str(script), str(pred_path), str(gt_path)])[0])
    rows.append((f"{n_pred // 1000}k predictions, JSON files, fresh process", Spread.of(cli_times),
                 "nuScenes: json.load + boxes + accumulate", Spread.of(ns_times)))
    return rows


# --- 3. memory ------------------------------------------------------------------------------------


def memory_rows(n_frames: int, per_frame: int, workdir: Path) -> None:
    print()
    print("peak RSS of the zendar-eval CLI as a subprocess (JSON parsing included)")
    print(f"{'predictions':>12} {'JSON MB':>8} {'wall s':>7} {'peak RSS MB':>12} {'added bytes per added prediction':>34}")
    previous = None
    for frames in (n_frames // 100, n_frames // 10, n_frames):
        ground_truth, predictions = synthetic(frames, per_frame)
        pred_path, gt_path = workdir / f"mem_pred_{frames}.json", workdir / f"mem_gt_{frames}.json"
        pred_path.write_bytes(orjson.dumps(predictions))
        gt_path.write_bytes(orjson.dumps(ground_truth))
        del ground_truth, predictions
        size_mb = (pred_path.stat().st_size + gt_path.stat().st_size) / 1e6
        seconds, rss = wait_rss(cli_command(pred_path, gt_path, workdir / f"mem-out-{frames}"))
        n = frames * per_frame
        slope = f"{(rss - previous[1]) / (n - previous[0]):>34.0f}" if previous else f"{'-':>34}"
        print(f"{n:>12,} {size_mb:>8.0f} {seconds:>7.2f} {rss / 1e6:>12.0f} {slope}")
        previous = (n, rss)
        pred_path.unlink()
        gt_path.unlink()


def print_rows(title: str, rows: list[tuple]) -> None:
    print()
    print(title)
    print(f"{'case':<54} {'package s':>22} {'reference':<42} {'reference s':>22} {'ratio':>7}")
    for label, package, ref_name, reference in rows:
        print(f"{label:<54} {package.text():>22} {ref_name:<42} {reference.text():>22} "
              f"{reference.median / package.median:>6.1f}x")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=100_000)
    parser.add_argument("--per-frame", type=int, default=10)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--nuscenes-frames", type=int, default=20_000, help="frames of the devkit comparison")
    parser.add_argument("--skip-memory", action="store_true")
    args = parser.parse_args()
    print_environment(("numpy", "numba", "orjson", "nuscenes-devkit", "pyquaternion"))
    evaluate(*synthetic(10, 3)[::-1])  # compile the kernels (cached on disk afterwards)

    with tempfile.TemporaryDirectory(prefix="bench-eval-") as tmp:
        workdir = Path(tmp)
        ground_truth, predictions = synthetic(args.frames, args.per_frame)
        n_gt = sum(map(len, ground_truth["frames"].values()))
        print(f"{args.frames:,} frames, {args.frames * args.per_frame:,} predictions, {n_gt:,} ground truths; "
              "times: median (min-max) s")
        rows = plain_loop_rows(ground_truth, predictions, args.repeats, workdir)
        del ground_truth, predictions
        print_rows("1. against the plain loop of the same protocol", rows)
        rows = nuscenes_rows(args.nuscenes_frames, args.per_frame, args.repeats, workdir)
        if rows:
            print_rows("2. against the nuScenes devkit (same predictions, identical TP/FP)", rows)
        if not args.skip_memory:
            memory_rows(args.frames, args.per_frame, workdir)
    print_load_after()


if __name__ == "__main__":
    main()
