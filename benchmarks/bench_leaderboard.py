"""Claims: the leaderboard validates and scores submissions at a steady rate on 2 cores, for a test
split of the demo's size and for 100,000 frames, and serves its ranking page to 50 concurrent
readers with a bounded latency.

Run: python benchmarks/bench_leaderboard.py [--demo-submissions 20] [--large-frames 100000]
     [--large-submissions 3] [--readers 50] [--reads-per-reader 20] [--entries 30]

Each part starts a real ``zendar-leaderboard serve`` (default settings: one scorer process,
200 bootstrap resamples) on 127.0.0.1 with synthetic hidden labels, uploads from as many teams as
there are submissions, all at once, and times from the first upload to the last score: the rate
includes the server's validation before queueing, the queue, and the scorer. Readers then fetch
``GET /`` in a bounded loop (loopback only). The load average is printed before and after: figures
taken at a load above the CPU count are upper bounds on the time.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import random
import statistics
import sys
import tempfile
import time
import urllib.request
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.leaderboard.conftest import meta, start_server  # noqa: E402
from tests.leaderboard.helpers import post_submission, wait_done  # noqa: E402
from zendar_leaderboard.ground_truth import TestSplit, divide_frames, frames_sha256  # noqa: E402
from zendar_leaderboard.scoring import score_submission  # noqa: E402
from zendar_leaderboard.store import Store  # noqa: E402
from zendar_leaderboard.submission import check_submission  # noqa: E402


def labels(n_scenes: int, frames_per_scene: int, cars: tuple[int, int], seed: int = 0) -> dict:
    """Hidden labels: cars at all bearings between 3 and 58 m."""
    rng = random.Random(seed)
    frames = {}
    for s in range(n_scenes):
        for t in range(frames_per_scene):
            frame = []
            for _ in range(rng.randint(*cars)):
                r, bearing = rng.uniform(3, 58), rng.uniform(-math.pi, math.pi)
                frame.append({"x": r * math.cos(bearing), "y": r * math.sin(bearing)})
            frames[f"scene-{s:04d}/{1_600_000_000_000_000_000 + 100_000_000 * t}"] = frame
    return {"frames": frames, "split": "test"}


def predictions(gt: dict, seed: int) -> bytes:
    """Noisy-oracle predictions: 80% of the cars jittered by 1 m, plus one clutter detection per frame."""
    rng = random.Random(seed)
    results = {}
    for frame_id, cars in gt["frames"].items():
        detections = [{"x": round(c["x"] + rng.gauss(0, 1), 3), "y": round(c["y"] + rng.gauss(0, 1), 3),
                       "score": round(rng.random(), 3)} for c in cars if rng.random() < 0.8]
        detections.append({"x": round(rng.uniform(-50, 50), 3), "y": round(rng.uniform(-50, 50), 3),
                           "score": round(rng.random() * 0.5, 3)})
        results[frame_id] = detections
    return json.dumps({"meta": meta(method=f"oracle-{seed}"), "results": results}).encode()


def throughput(name: str, gt: dict, n_submissions: int, work: Path, extra: tuple[str, ...] = ()) -> Path:
    """Upload n submissions from n teams at once; print submissions per minute. Returns the db."""
    gt_path = work / f"{name}-gt.json"
    gt_path.write_text(json.dumps(gt))
    db = work / f"{name}.db"
    store = Store(db)
    tokens = [store.add_team(f"{name}-{k}") for k in range(n_submissions + 1)]
    bodies = [predictions(gt, seed=k) for k in range(n_submissions + 1)]
    n_frames = len(gt["frames"])
    n_predictions = sum(body.count(b'"score"') for body in bodies) // n_submissions
    print(f"\n{name}: {n_frames:,} frames, {sum(map(len, gt['frames'].values())):,} hidden cars; "
          f"{n_submissions} submissions of {len(bodies[0]) / 1e6:.1f} MB, {n_predictions:,} predictions each")
    started = time.monotonic()
    server = start_server(db, gt_path, *extra)
    # One submission first, untimed: the scorer process starts and compiles while it is scored.
    _, warm = post_submission(server.url, tokens[-1], bodies[-1])
    wait_done(server.url, tokens[-1], warm["id"], timeout_s=3600)
    print(f"  server and scorer ready in {time.monotonic() - started:.1f} s (labels loaded, evaluator compiled)")
    try:
        started = time.monotonic()
        with ThreadPoolExecutor(max_workers=min(n_submissions, 16)) as pool:
            answers = list(pool.map(lambda k: post_submission(server.url, tokens[k], bodies[k]), range(n_submissions)))
        accepted = time.monotonic() - started
        assert all(status == 202 for status, _ in answers), answers[:3]
        for k, (_, answer) in enumerate(answers):
            assert wait_done(server.url, tokens[k], answer["id"], timeout_s=3600)["status"] == "scored"
        elapsed = time.monotonic() - started
    finally:
        server.stop()
    print(f"  all {n_submissions} accepted (validated, recorded) after {accepted:.1f} s; all scored after {elapsed:.1f} s")
    print(f"  => {60 * n_submissions / elapsed:.1f} submissions validated and scored per minute "
          f"({elapsed / n_submissions:.2f} s each)")
    # The same work in this process, for its CPU time (wall time above depends on the machine's load).
    split = TestSplit(gt["frames"], "test", frames_sha256(gt["frames"]), *divide_frames(list(gt["frames"])))
    score_submission(check_submission(bodies[-1], list(gt["frames"])).document, split, bootstrap=200)  # compiles
    cpu_started = time.process_time()
    for body in bodies[:n_submissions]:
        checked = check_submission(body, list(gt["frames"]))
        score_submission(checked.document, split, bootstrap=200)
        check_submission(body, list(gt["frames"]))  # the server checks before queueing, the scorer again
    cpu = (time.process_time() - cpu_started) / n_submissions
    print(f"  CPU per submission (two checks + scoring, in one process): {cpu:.3f} s "
          f"=> {60 / cpu:.0f} per minute per core")
    return db


def read_latency(db: Path, gt: dict, work: Path, readers: int, reads_per_reader: int) -> None:
    gt_path = work / "latency-gt.json"
    gt_path.write_text(json.dumps(gt))
    server = start_server(db, gt_path)
    n_entries = len(Store(db).scored_entries())
    try:
        def reader(_: int) -> list[float]:
            times = []
            for _ in range(reads_per_reader):
                t0 = time.perf_counter()
                with urllib.request.urlopen(f"{server.url}/", timeout=60) as response:
                    assert response.status == 200 and response.read()
                times.append(time.perf_counter() - t0)
            return times

        started = time.monotonic()
        with ThreadPoolExecutor(max_workers=readers) as pool:
            latencies = sorted(t for times in pool.map(reader, range(readers)) for t in times)
        elapsed = time.monotonic() - started
    finally:
        server.stop()
    q = statistics.quantiles(latencies, n=100)
    print(f"\nranking page (GET /, {n_entries} entries): {readers} concurrent readers x {reads_per_reader} requests")
    print(f"  latency ms: median {1e3 * q[49]:.1f}, p95 {1e3 * q[94]:.1f}, p99 {1e3 * q[98]:.1f}, max {1e3 * latencies[-1]:.1f}")
    print(f"  {len(latencies) / elapsed:.0f} pages per second")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--demo-submissions", type=int, default=20)
    parser.add_argument("--large-frames", type=int, default=100_000)
    parser.add_argument("--large-submissions", type=int, default=3)
    parser.add_argument("--readers", type=int, default=50)
    parser.add_argument("--reads-per-reader", type=int, default=20)
    parser.add_argument("--entries", type=int, default=30, help="scored entries on the ranking page")
    parser.add_argument("--parts", default="demo,large,latency", help="which parts to run (comma-separated)")
    args = parser.parse_args()
    print(f"load average before: {' '.join(f'{v:.2f}' for v in os.getloadavg())} ({os.cpu_count()} CPUs)")
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        # The demo profile's test split: one 6 s scene of 10 Hz SAR frames, 5 to 10 moving cars.
        demo = labels(n_scenes=1, frames_per_scene=60, cars=(5, 10))
        parts = set(args.parts.split(","))
        if "demo" in parts:
            throughput("demo-size", demo, args.demo_submissions, work)
        if "large" in parts:
            large = labels(n_scenes=args.large_frames // 200, frames_per_scene=200, cars=(1, 5))
            throughput(f"{args.large_frames:,}-frames", large, args.large_submissions, work)
        if "latency" in parts:
            entries_db = throughput("ranking", demo, args.entries, work)  # its entries fill the ranking page
            read_latency(entries_db, demo, work, args.readers, args.reads_per_reader)
    print(f"\nload average after: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")


if __name__ == "__main__":
    main()
