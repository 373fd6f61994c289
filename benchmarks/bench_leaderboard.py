"""Claims: the leaderboard validates and scores submissions at a steady rate on 2 cores, for a test
split of the demo's size and for 100,000 frames, and serves its ranking page to 50 concurrent
readers with a bounded latency; an upload's peak memory in the server stays within 40 times its
size, valid or hostile; two slow-body uploads do not slow other uploads down.

Run: python benchmarks/bench_leaderboard.py [--demo-submissions 20] [--large-frames 100000]
     [--large-submissions 3] [--readers 50] [--reads-per-reader 20] [--entries 30]
     [--parts demo,large,latency,memory,slow]

Each part starts a real ``zendar-leaderboard serve`` (default settings: one scorer process,
200 bootstrap resamples) on 127.0.0.1 with synthetic hidden labels, uploads from as many teams as
there are submissions, all at once, and times from the first upload to the last score: the rate
includes the server's validation before queueing, the queue, and the scorer. Readers then fetch
``GET /`` in a bounded loop (loopback only). The load average is printed before and after: figures
taken at a load above the CPU count are upper bounds on the time.

``memory``: a fresh server per upload; its peak resident memory is reset (``/proc/PID/clear_refs``)
before the upload and read (``VmHWM``) after it is answered: the peak per upload is the growth over
the resident memory before. ``slow``: uploads per second of a small valid file, one after another,
with no other client and then with two slow-body uploads connected (each declares 1 MB and sends a
byte every 5 s).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import random
import select
import statistics
import sys
import tempfile
import threading
import time
import urllib.request
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.leaderboard.adversarial.rawhttp import connect, upload_head  # noqa: E402
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


def _status_kb(pid: int, field: str) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1])
    raise KeyError(field)


def _peak_growth_bytes(server, token: str, body: bytes) -> tuple[int, int]:
    """(status, growth of the server's peak resident memory over its resident memory before) of one upload."""
    pid = server.process.pid
    Path(f"/proc/{pid}/clear_refs").write_text("5")  # the peak resident size starts again from now
    before_kb = _status_kb(pid, "VmRSS")
    status, _ = post_submission(server.url, token, body)
    return status, 1024 * (_status_kb(pid, "VmHWM") - before_kb)


def upload_memory(work: Path) -> None:
    """Peak server memory per upload, for dense valid uploads and hostile ones of 1 and 3 MB."""
    print("\npeak server memory per upload (fresh server each, default settings)")
    cases = []
    for size_mb, n_scenes in ((1, 26), (3, 78)):
        gt = labels(n_scenes=n_scenes, frames_per_scene=200, cars=(1, 5))
        body = predictions(gt, seed=1)
        cases.append((f"dense valid, {len(gt['frames']):,} frames", gt, body))
    small_gt = labels(n_scenes=1, frames_per_scene=60, cars=(5, 10))
    for size_mb in (1, 3):
        n = size_mb * 1_000_000
        empty = b'{"meta":{},"results":{"a/1":[' + b"{}," * (n // 3) + b"{}]}}"
        one_key = b'{"meta":{},"results":{"a/1":[' + b'{"a":0.5},' * (n // 10) + b"{}]}}"
        cases.append(("hostile [{},{},...]", small_gt, empty))
        cases.append(('densest allowed [{"a":0.5},...]', small_gt, one_key))
    cases.sort(key=lambda case: len(case[2]))
    for k, (name, gt, body) in enumerate(cases):
        gt_path = work / f"memory-{k}-gt.json"
        gt_path.write_text(json.dumps(gt))
        db = work / f"memory-{k}.db"
        store = Store(db)
        warm_token, token = store.add_team("warm"), store.add_team("measured")
        server = start_server(db, gt_path)
        try:
            post_submission(server.url, warm_token, b'{"meta":{},"results":{"a/1":[{}]}}')  # first-use costs
            status, growth = _peak_growth_bytes(server, token, body)
        finally:
            server.stop()
        print(f"  {name:<36} {len(body) / 1e6:5.2f} MB -> {status}: peak +{growth / 1e6:6.1f} MB "
              f"= {growth / len(body):4.1f} x the upload")


class SlowBody(threading.Thread):
    """An upload that declares 1 MB and sends one byte every 5 s until stopped."""

    def __init__(self, url: str, token: str) -> None:
        super().__init__(daemon=True)
        self.sock = connect(url)
        self.sock.sendall(upload_head(token, 1_000_000))
        self.stopped = threading.Event()

    def run(self) -> None:
        try:
            while not self.stopped.wait(5.0) and not select.select([self.sock], [], [], 0)[0]:
                self.sock.sendall(b" ")
        except OSError:
            pass
        finally:
            self.sock.close()


def slow_body_throughput(work: Path, n_uploads: int) -> None:
    """Uploads per second of a small valid file with no other client, then with two slow bodies connected."""
    gt = labels(n_scenes=1, frames_per_scene=60, cars=(5, 10))
    gt_path = work / "slow-gt.json"
    gt_path.write_text(json.dumps(gt))
    db = work / "slow.db"
    store = Store(db)
    token = store.add_team("uploader")
    attacker_tokens = [store.add_team(f"slow-{k}") for k in range(2)]
    body = predictions(gt, seed=1)
    server = start_server(db, gt_path, "--quota", str(2 * n_uploads + 1))
    try:
        post_submission(server.url, token, body)  # warm-up
        print(f"\nuploads of a {len(body) / 1e3:.0f} kB valid file, {n_uploads} one after another (default settings)")
        for label, n_slow in (("no other client", 0), ("2 slow-body uploads connected", 2)):
            slow = [SlowBody(server.url, attacker_tokens[k]) for k in range(n_slow)]
            for attacker in slow:
                attacker.start()
            time.sleep(0.5 if slow else 0)
            started = time.monotonic()
            statuses = [post_submission(server.url, token, body)[0] for _ in range(n_uploads)]
            elapsed = time.monotonic() - started
            for attacker in slow:
                attacker.stopped.set()
                attacker.join()
            assert statuses == [202] * n_uploads, statuses
            print(f"  {label:<32} {n_uploads / elapsed:6.1f} uploads/s")
    finally:
        server.stop()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--demo-submissions", type=int, default=20)
    parser.add_argument("--large-frames", type=int, default=100_000)
    parser.add_argument("--large-submissions", type=int, default=3)
    parser.add_argument("--readers", type=int, default=50)
    parser.add_argument("--reads-per-reader", type=int, default=20)
    parser.add_argument("--entries", type=int, default=30, help="scored entries on the ranking page")
    parser.add_argument("--slow-uploads", type=int, default=40, help="uploads timed in the slow-body part")
    parser.add_argument("--parts", default="demo,large,latency,memory,slow", help="which parts to run (comma-separated)")
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
        if "memory" in parts:
            upload_memory(work)
        if "slow" in parts:
            slow_body_throughput(work, args.slow_uploads)
    print(f"\nload average after: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")


if __name__ == "__main__":
    main()
