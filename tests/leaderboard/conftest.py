"""Ground truth, submissions and servers for the leaderboard tests.

The ground truth is built by hand in the evaluator's format: several scenes, cars in all three
range bands on every side of the ego vehicle (ahead, behind, to the left and right), timestamps
that do not sort as strings.
"""

from __future__ import annotations

import json
import math
import os
import random
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import pytest

from zendar_leaderboard.meta import BOOLEAN_FIELDS

SERVE_TIMEOUT_S = 120.0


def ground_truth(n_scenes: int = 4, frames_per_scene: int = 5, seed: int = 0) -> dict:
    """``{"frames": {...}}`` with 2 to 5 cars per frame between 3 m and 58 m, all bearings."""
    rng = random.Random(seed)
    frames = {}
    for s in range(n_scenes):
        for t in range(frames_per_scene):
            cars = []
            for _ in range(rng.randint(2, 5)):
                range_m = rng.uniform(3.0, 58.0)
                bearing = rng.uniform(-math.pi, math.pi)
                cars.append({"x": range_m * math.cos(bearing), "y": range_m * math.sin(bearing), "length": 4.5})
            # 900 ms then 1000 ms ...: as strings, "…/1000…" would sort before "…/900…".
            frames[f"scene-{s:02d}/{900_000_000 + 100_000_000 * t}"] = cars
    return {"frames": frames, "split": "test"}



def ground_truth_file(directory: Path, **kwargs) -> tuple[dict, Path]:
    """:func:`ground_truth` (``kwargs`` passed on) and ``directory / "gt.json"`` holding it."""
    gt = ground_truth(**kwargs)
    path = directory / "gt.json"
    path.write_text(json.dumps(gt))
    return gt, path

def meta(**overrides) -> dict:
    """A complete, valid ``meta``."""
    value = {
        "method": "noisy oracle",
        "team": "testers",
        "contact": "lead@example.org",
        "description": "ground truth jittered by 1 m, 20% missed, plus clutter",
        "url": "https://example.org/method",
        **{name: False for name in BOOLEAN_FIELDS},
        "uses_sar": True,
        "runtime_ms": 12.5,
        "hardware": "1 CPU core",
    }
    value.update(overrides)
    return value


def submission(gt: dict, seed: int = 1, **meta_overrides) -> dict:
    """Noisy-oracle predictions for every frame of ``gt``."""
    rng = random.Random(seed)
    results = {}
    for frame_id, cars in gt["frames"].items():
        detections = [
            {"x": c["x"] + rng.gauss(0, 1.0), "y": c["y"] + rng.gauss(0, 1.0), "score": round(rng.random(), 3)}
            for c in cars
            if rng.random() < 0.8
        ]
        detections.append({"x": rng.uniform(-50, 50), "y": rng.uniform(-50, 50), "score": round(rng.random() * 0.5, 3)})
        results[frame_id] = detections
    return {"meta": meta(**meta_overrides), "results": results}


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


@dataclass
class ServerProcess:
    """A ``zendar-leaderboard serve`` process on 127.0.0.1."""

    process: subprocess.Popen
    url: str
    db: Path
    gt: Path
    log: Path

    def kill(self) -> None:
        """SIGKILL the server and its scorer (its process group), as a crash would."""
        if self.process.poll() is None:
            os.killpg(self.process.pid, signal.SIGKILL)
        self.process.wait(timeout=30)

    def stop(self) -> None:
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGINT)
            try:
                self.process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.kill()


def start_server(db: Path, gt: Path, *extra: str) -> ServerProcess:
    """Start ``serve`` on a free port and wait until it answers."""
    log = db.with_suffix(f".{time.monotonic_ns()}.log")
    command = [sys.executable, "-m", "zendar_leaderboard.cli", "serve", "--gt", str(gt), "--db", str(db),
               "--host", "127.0.0.1", "--port", "0", *extra]
    with open(log, "wb") as out:
        process = subprocess.Popen(command, stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
    deadline = time.monotonic() + SERVE_TIMEOUT_S
    while time.monotonic() < deadline:
        text = log.read_text(errors="replace")
        match = re.search(r"serving (http://127\.0\.0\.1:\d+)/", text)
        if match:
            return ServerProcess(process, match.group(1), db, gt, log)
        if process.poll() is not None:
            raise RuntimeError(f"server exited with {process.returncode}:\n{text}")
        time.sleep(0.1)
    process.kill()
    raise RuntimeError(f"server did not start within {SERVE_TIMEOUT_S} s:\n{log.read_text()}")


@pytest.fixture
def gt_file(tmp_path) -> tuple[Path, dict]:
    document = ground_truth()
    path = tmp_path / "gt.json"
    path.write_text(json.dumps(document))
    return path, document


class InProcessServer:
    """Store, scorer and HTTP server of one leaderboard, in this process (the scorer is a child)."""

    def __init__(self, tmp: Path, gt_document: dict, **settings) -> None:
        from zendar_dataset.eval.protocol import PROTOCOL_VERSION
        from zendar_leaderboard.ground_truth import load_test_split
        from zendar_leaderboard.scheduler import ScorerSettings, ScoringService
        from zendar_leaderboard.server import LeaderboardHTTPServer, ServerSettings
        from zendar_leaderboard.store import Store

        self.gt = tmp / "gt.json"
        self.gt.write_text(json.dumps(gt_document))
        self.db = tmp / "board.db"
        self.test_split = load_test_split(self.gt)
        self.store = Store(self.db)
        self.store.recover(PROTOCOL_VERSION, self.test_split.sha256)
        quota = settings.pop("quota", 3)
        max_bytes = settings.pop("max_bytes", 5_000_000)
        self.scoring = ScoringService(self.store, ScorerSettings(
            gt=str(self.gt), split=None, db=str(self.db), gt_sha256=self.test_split.sha256,
            **{"bootstrap": 20, **settings},
        ))
        self.scoring.start()
        self.http = LeaderboardHTTPServer(
            ("127.0.0.1", 0), ServerSettings(self.store, self.test_split, self.scoring, quota=quota, max_bytes=max_bytes)
        )
        self.url = f"http://127.0.0.1:{self.http.server_address[1]}"
        self.thread = threading.Thread(target=self.http.serve_forever, daemon=True)
        self.thread.start()

    def stop(self) -> None:
        self.http.shutdown()
        self.http.server_close()
        self.scoring.stop()


@pytest.fixture(scope="module")
def board(tmp_path_factory):
    """One in-process leaderboard per test module (quota 3, 5 MB uploads)."""
    server = InProcessServer(tmp_path_factory.mktemp("board"), ground_truth())
    yield server
    server.stop()
