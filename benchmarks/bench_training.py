"""Claim: ``train`` runs at the speed of a plain PyTorch loop on demo-sized inputs (within 10 %), for
each detector at width 0.25 (``--width``; the demo config trains at 0.125); it reports training frames
per second. ``train`` runs channels-last (``MEMORY_FORMAT``), the plain loop NCHW, as a user writes it.
A third side is ``train`` with torch's deterministic mode filling new tensors with NaN (its default,
``FILL_UNINITIALIZED_MEMORY`` True), which ``train`` switches off: the column "fill / package" is
what that costs.

Run: python benchmarks/bench_training.py [--models fpn-resnet34 densenet-37 densenet-67] [--width 0.25]
                                         [--frames 60] [--repeats 3] [--threads 2]

Inputs: one demo scene of one radar: ``--frames`` maps of 4 antennas × 256 range × 64 Doppler bins,
stacked K = 3 (12 channels, ``--frames - 2`` samples), masks with 1 % moving cells; batch 16, one
epoch, Adam at lr 1e-3, as the demo config.

1. Package: ``zendar_baselines.cnn.training.train`` (distributed sampler, masked loss, progress bar off,
   one checkpoint written with its SHA-256 and manifest per call).
2. Plain: the loop a user would write: ``DataLoader(shuffle=True)``, Adam, ``BCEWithLogits`` with the
   same positive weight and uncertain cells masked out, no checkpoint.

Each repeat starts both from the same initial weights, alternating call by call. Frames/s = samples
per second of wall time (one sample = one K-map window). Threads: ``--threads`` for both.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from harness import Spread, interleaved, print_environment, print_load_after

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from zendar_baselines.bench.configs import MODEL_NAMES, Schedule  # noqa: E402
from zendar_baselines.cnn.mask_frames import MaskFrames  # noqa: E402
from zendar_baselines.cnn.models import build_model  # noqa: E402
from zendar_baselines.cnn import training  # noqa: E402
from zendar_baselines.cnn.training import positive_class_weight, seed_everything, train  # noqa: E402

N_RX, N_RANGE, N_DOPPLER, WINDOW = 4, 256, 64, 3


def demo_scene(n_frames: int, seed: int = 0) -> MaskFrames:
    """Normalised maps (unit-spread noise, 1 % of cells a bright moving target) and their masks."""
    rng = np.random.default_rng(seed)
    maps = rng.normal(0.0, 0.56, size=(n_frames, N_RX, N_RANGE, N_DOPPLER)).astype(np.float32)
    masks = np.zeros((n_frames, N_RANGE, N_DOPPLER), dtype=np.uint8)
    moving = rng.random((n_frames, N_RANGE, N_DOPPLER)) < 0.01
    masks[moving] = 1
    masks[rng.random((n_frames, N_RANGE, N_DOPPLER)) < 0.005] = 2
    maps += 3.0 * moving[:, None]
    return MaskFrames(maps, masks, window=WINDOW)


def plain_epoch(model: torch.nn.Module, data: MaskFrames, schedule: Schedule, pos_weight: float, seed: int) -> None:
    """One epoch of the loop a user would write by hand."""
    loader = torch.utils.data.DataLoader(
        data, batch_size=schedule.batch_size, shuffle=True, generator=torch.Generator().manual_seed(seed)
    )
    optimizer = torch.optim.Adam(model.parameters(), lr=schedule.lr)
    weight = torch.tensor(pos_weight)
    model.train()
    for inputs, targets in loader:
        labelled = (targets != 2).float()
        per_cell = F.binary_cross_entropy_with_logits(
            model(inputs)[:, 0], (targets == 1).float(), pos_weight=weight, reduction="none"
        )
        loss = (per_cell * labelled).sum() / labelled.sum().clamp(min=1.0)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()


def frames_per_second(n_samples: int, seconds: Spread) -> str:
    """``median (min-max)`` samples per second of a spread of wall times."""
    return f"{n_samples / seconds.median:.2f} ({n_samples / seconds.max:.2f}-{n_samples / seconds.min:.2f})"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--models", nargs="+", default=list(MODEL_NAMES), choices=MODEL_NAMES)
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--width", type=float, default=0.25, help="the models' width scale")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    training.TRAINING_THREADS = args.threads  # what train() pins while training
    print_environment(["torch", "numpy"])
    print(f"threads: {args.threads} (torch intra-op) for both sides")
    data = demo_scene(args.frames)
    schedule = Schedule(lr=1e-3, batch_size=16, epochs=1)
    pos_weight = positive_class_weight(data)
    print(f"inputs: {len(data)} samples of [{data.in_channels}, {N_RANGE}, {N_DOPPLER}], batch {schedule.batch_size}, 1 epoch")
    print(f"{'model':<14} {'package frames/s':>24} {'plain frames/s':>24} {'package / plain time':>22} "
          f"{'fill / package time':>20}")
    with tempfile.TemporaryDirectory() as scratch:
        for name in args.models:
            seed_everything(0)
            initial = build_model(name, data.in_channels, args.width).state_dict()
            calls = {"package": 0}

            def package(fill: bool = False) -> None:
                seed_everything(0)
                model = build_model(name, data.in_channels, args.width)
                model.load_state_dict(initial)
                calls["package"] += 1
                out_dir = Path(scratch) / f"{name}-{calls['package']}"
                training.FILL_UNINITIALIZED_MEMORY = fill
                try:
                    train(model, data, schedule, seed=0, out_dir=out_dir, progress=False)
                finally:
                    training.FILL_UNINITIALIZED_MEMORY = False

            def plain() -> None:
                model = build_model(name, data.in_channels, args.width)
                model.load_state_dict(initial)
                plain_epoch(model, data, schedule, pos_weight, seed=0)

            spreads = interleaved({"package": package, "plain": plain, "fill": lambda: package(fill=True)},
                                  repeats=args.repeats)
            ratio = spreads["package"].median / spreads["plain"].median
            fill_ratio = spreads["fill"].median / spreads["package"].median
            package_rate = frames_per_second(len(data), spreads["package"])
            plain_rate = frames_per_second(len(data), spreads["plain"])
            print(f"{name:<14} {package_rate:>24} {plain_rate:>24} {ratio:>22.3f} {fill_ratio:>20.3f}")
    print_load_after()


if __name__ == "__main__":
    main()
