"""Size and speed of the CNN detectors (FPN-ResNet-34, zoom-out DenseNet-37 and -67).

    python benchmarks/bench_models.py                  # CPU, demo and paper configurations
    python benchmarks/bench_models.py --skip-paper     # CPU, demo only (under a minute)
    python benchmarks/bench_models.py --device cuda    # the same on a GPU (skipped without one)

Per architecture and configuration:

* trainable parameters;
* inference, ms per stacked frame, at batch 1 and batch 8 (``torch.inference_mode``, eval mode,
  after warm-up), min / median / max over repeats;
* training throughput, frames/s: forward, BCE loss, backward and an Adam step on a fixed random
  batch (8 frames demo, 2 frames paper), after a warm-up step.

Configurations: ``demo`` is 12 input channels (3 stacked maps x 4 antennas) of 256 range x 64
Doppler bins at the demo config's width_scale (0.125); ``paper`` is 12 channels of 512 x 256 at the published widths.
The paper size on a CPU gets fewer repeats (its batch-8 inference once, after the batch-1 warm-up),
so its spread says little. There is no peer row: no published implementation of these detectors
exists to compare with. Threads: torch intra-op threads, printed (``--threads`` to change); on a
machine shared with other work, ``--threads 1`` gives far steadier figures than threads that wait
for each other at every operator.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass

import torch
import torch.nn.functional as F
from harness import Spread, print_environment, print_load_after, time_calls

from zendar_baselines.bench.configs import get_config
from zendar_baselines.cnn.models import MODEL_NAMES, build_model, parameter_count


@dataclass(frozen=True)
class Setting:
    """One input configuration and how often to time it."""

    name: str
    in_channels: int
    range_bins: int
    doppler_bins: int
    width_scale: float
    train_batch: int
    repeats_batch1: int
    repeats_batch8: int
    repeats_train: int


INFERENCE_BATCHES = (1, 8)


def settings(device: str) -> dict[str, Setting]:
    """The demo and paper settings; the paper size on a CPU gets the fewest repeats that still time it."""
    paper_repeats = (2, 1, 1) if device == "cpu" else (20, 10, 10)
    demo, paper = get_config("demo"), get_config("paper")
    return {
        "demo": Setting("demo", demo.window * 4, 256, 64, demo.width_scale, 8, 10, 5, 5),
        "paper": Setting("paper", paper.window * 4, 512, 256, paper.width_scale, 2, *paper_repeats),
    }


def synchronised(fn, device: str):
    """``fn`` followed by a wait for the device, so that a GPU's queued work is inside the timing."""
    if device == "cpu":
        return fn

    def call() -> None:
        fn()
        torch.cuda.synchronize(device)

    return call


def inference_ms_per_frame(model: torch.nn.Module, setting: Setting, batch: int, device: str, repeats: int,
                           warmup: int) -> Spread:
    model.eval()
    x = torch.randn(batch, setting.in_channels, setting.range_bins, setting.doppler_bins, device=device)

    def forward() -> None:
        with torch.inference_mode():
            model(x)

    return time_calls(synchronised(forward, device), repeats=repeats, warmup=warmup).scaled(1e3 / batch)


def training_frames_per_s(model: torch.nn.Module, setting: Setting, device: str) -> Spread:
    model.train()
    generator = torch.Generator(device=device).manual_seed(0)
    shape = (setting.train_batch, setting.in_channels, setting.range_bins, setting.doppler_bins)
    x = torch.randn(shape, generator=generator, device=device)
    labels = (torch.rand((shape[0], 1, *shape[2:]), generator=generator, device=device) < 0.01).float()
    optimizer = torch.optim.Adam(model.parameters(), lr=1e-4)

    def step() -> None:
        loss = F.binary_cross_entropy_with_logits(model(x), labels)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()

    seconds = time_calls(synchronised(step, device), repeats=setting.repeats_train, warmup=1)
    # Frames per second: the fastest step gives the highest rate, so min and max swap.
    rates = sorted(setting.train_batch / value for value in (seconds.min, seconds.median, seconds.max))
    return Spread(rates[0], rates[1], rates[2], seconds.repeats)


def measure(setting: Setting, device: str) -> None:
    print(f"\n{setting.name}: {setting.in_channels} channels x {setting.range_bins} range x "
          f"{setting.doppler_bins} Doppler bins, width_scale {setting.width_scale}, training batch "
          f"{setting.train_batch}; repeats b1 {setting.repeats_batch1}, b8 {setting.repeats_batch8}, "
          f"train {setting.repeats_train}")
    print(f"{'model':14s} {'parameters':>11s} {'ms/frame b1, median (min-max)':>32s} "
          f"{'ms/frame b8, median (min-max)':>32s} {'train frames/s, median (min-max)':>34s}")
    for name in MODEL_NAMES:
        torch.manual_seed(0)
        model = build_model(name, setting.in_channels, setting.width_scale).to(device)
        batch1 = inference_ms_per_frame(model, setting, 1, device, setting.repeats_batch1, warmup=1)
        # On a CPU the paper's batch 8 runs for many seconds; the batch-1 calls were its warm-up there.
        warmup8 = 0 if device == "cpu" and setting.name == "paper" else 1
        batch8 = inference_ms_per_frame(model, setting, 8, device, setting.repeats_batch8, warmup=warmup8)
        training = training_frames_per_s(model, setting, device)
        print(f"{name:14s} {parameter_count(model):11,d} {batch1.text('.4g'):>32s} {batch8.text('.4g'):>32s} "
              f"{training.text('.4g'):>34s}", flush=True)
        del model
        if device != "cpu":
            torch.cuda.empty_cache()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--device", default="cpu", help="'cuda' (or 'cuda:N') times the same on a GPU")
    parser.add_argument("--skip-paper", action="store_true", help="only the demo configuration")
    parser.add_argument("--threads", type=int, default=None, help="torch intra-op threads (default: torch's)")
    args = parser.parse_args()
    if args.device.startswith("cuda") and not torch.cuda.is_available():
        print(f"--device {args.device}: no CUDA device here; the detectors were not timed on a GPU.")
        return
    if args.threads is not None:
        torch.set_num_threads(args.threads)
    print_environment(("torch",))
    where = torch.cuda.get_device_name(args.device) if args.device.startswith("cuda") else "CPU"
    print(f"device: {where}; torch intra-op threads: {torch.get_num_threads()}")
    for name, setting in settings(args.device).items():
        if name == "paper" and args.skip_paper:
            continue
        measure(setting, args.device)
    print_load_after()


if __name__ == "__main__":
    main()
