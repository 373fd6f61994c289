"""Claim: ``zendar-bench`` trains two seeds sooner side by side on one thread each than one after the
other on two threads each (docs/baselines.md, "Seeds side by side").

Run: python benchmarks/bench_seed_workers.py [--models fpn-resnet34 densenet-67] [--epochs 12] [--frames 60]

Inputs: :func:`bench_training.demo_scene` (4 antennas × 256 × 64, K = 3, batch 16), models at the demo
config's width 0.125, ``--epochs`` epochs of ``zendar_baselines.cnn.training.train`` per seed.

1. One after the other: one process trains seed 0 then seed 1, torch on 2 intra-op threads.
2. Side by side: two processes start together, each training one seed on 1 thread (what the bench's
   worker processes do).

Each training runs in a fresh interpreter (``--child``), so no thread pool carries over; the times are
wall seconds from start to the last seed's end, import of torch included in both.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from harness import print_environment, print_load_after

ROOT = Path(__file__).resolve().parents[1]
WIDTH_SCALE = 0.125


def child(model_name: str, threads: int, epochs: int, frames: int, seeds: list[int]) -> None:
    """Train ``seeds`` one after the other on ``threads`` intra-op threads."""
    sys.path.insert(0, str(ROOT))
    from bench_training import demo_scene

    from zendar_baselines.cnn import training
    from zendar_baselines.cnn.models import build_model
    from zendar_baselines.cnn.schedule import Schedule

    training.TRAINING_THREADS = threads  # what train() pins while training
    data = demo_scene(frames)
    for seed in seeds:
        training.seed_everything(seed)
        model = build_model(model_name, data.in_channels, WIDTH_SCALE)
        with tempfile.TemporaryDirectory() as out:
            training.train(model, data, Schedule(lr=1e-3, batch_size=16, epochs=epochs), seed=seed, out_dir=out,
                           progress=False)


def _command(model: str, threads: int, epochs: int, frames: int, seeds: list[int]) -> list[str]:
    return [sys.executable, __file__, "--child", model, str(threads), str(epochs), str(frames), *map(str, seeds)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--models", nargs="+", default=["fpn-resnet34", "densenet-67"])
    parser.add_argument("--epochs", type=int, default=12)
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--child", nargs="+", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        model, threads, epochs, frames, *seeds = args.child
        child(model, int(threads), int(epochs), int(frames), [int(s) for s in seeds])
        return
    print_environment(["torch", "numpy"])
    print("| model | one after the other, 2 threads (s) | side by side, 1 thread each (s) | speed-up |")
    print("|---|--:|--:|--:|")
    for model in args.models:
        started = time.perf_counter()
        subprocess.run(_command(model, 2, args.epochs, args.frames, [0, 1]), check=True)
        sequential_s = time.perf_counter() - started
        started = time.perf_counter()
        workers = [subprocess.Popen(_command(model, 1, args.epochs, args.frames, [seed])) for seed in (0, 1)]
        for worker in workers:
            if worker.wait() != 0:
                raise SystemExit(f"a side-by-side training of {model} failed")
        side_by_side_s = time.perf_counter() - started
        print(f"| {model} | {sequential_s:.1f} | {side_by_side_s:.1f} | {sequential_s / side_by_side_s:.2f} |", flush=True)
    print_load_after()


if __name__ == "__main__":
    main()
