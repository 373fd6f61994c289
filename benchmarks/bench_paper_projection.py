"""Projected training time of a ``zendar-bench`` configuration, from counted work.

    python benchmarks/bench_paper_projection.py [--config paper|gpu|demo|tiny] [--sustained-tflops 100] [--measure-cpu]

A projection, not a measurement. Per architecture it counts the floating-point operations of one
training step per frame at the configuration's map size and widths with ``torch.utils.flop_counter``
(forward + backward; convolutions and matrix products, which dominate), counts the frame-steps of
the configuration at its epoch ceilings (pretraining on every training cube's automatic labels,
fine-tuning and supervised-only training on the labelled part, for every seed; one window per cube,
the first ones padded; early stopping only shortens this), and divides by a sustained throughput.
The default 100 TFLOP/s is about 20 % of an H100/H200's dense TF32 peak (495 TFLOP/s), typical of
convolution training in float32 with TF32 enabled; pass another figure to rescale. With
``--measure-cpu`` it also times a few training steps of each architecture on this machine's CPU and
projects the same work at that measured throughput. Simulation, automatic labels and scoring are
left out.
"""

from __future__ import annotations

import argparse
import time

import torch
import torch.nn.functional as F
from torch.utils.flop_counter import FlopCounterMode

from zendar_baselines.bench.configs import get_config
from zendar_dataset.sim.profiles import get_profile

from zendar_baselines.cnn.models import build_model, parameter_count


def train_flops_per_frame(name: str, in_channels: int, shape: tuple[int, int], width_scale: float) -> int:
    """Forward + backward FLOPs of one frame (batch 1) at ``shape``."""
    model = build_model(name, in_channels, width_scale)
    x = torch.randn(1, in_channels, *shape)
    target = torch.zeros(1, 1, *shape)
    with FlopCounterMode(display=False) as counter:
        F.binary_cross_entropy_with_logits(model(x), target).backward()
    return int(counter.get_total_flops())


def frame_steps(config_name: str) -> dict[str, int]:
    """Frame-steps per seed of one architecture at the epoch ceilings: pretraining, fine-tuning and supervised-only."""
    config = get_config(config_name)
    profile = get_profile(config.sim_profile)
    n_train = round(config.n_scenes * 0.6)  # the simulator's default split ratios
    train_windows = 2 * n_train * int(round(profile.scene_duration_s * profile.radar_rate_hz))  # two radars, one per cube
    labelled_windows = max(1, round(config.labelled_fraction * train_windows))
    return {
        "pretrain": train_windows * config.pretrain.epochs,
        "finetune": labelled_windows * config.finetune.epochs,
        "supervised": labelled_windows * config.supervised.epochs,
    }


def measured_cpu_flops(name: str, in_channels: int, shape: tuple[int, int], width_scale: float, batch: int,
                       steps: int = 3) -> float:
    """Training FLOP/s of one architecture on this CPU: ``steps`` Adam steps of ``batch`` frames, after one warm-up."""
    model = build_model(name, in_channels, width_scale)
    optimiser = torch.optim.Adam(model.parameters(), lr=1e-4)
    x = torch.randn(batch, in_channels, *shape)
    target = torch.zeros(batch, 1, *shape)

    def step() -> None:
        optimiser.zero_grad()
        F.binary_cross_entropy_with_logits(model(x), target).backward()
        optimiser.step()

    step()
    started = time.perf_counter()
    for _ in range(steps):
        step()
    elapsed_s = time.perf_counter() - started
    return steps * batch * train_flops_per_frame(name, in_channels, shape, width_scale) / elapsed_s


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", default="paper", help="the zendar-bench configuration (default: paper)")
    parser.add_argument("--sustained-tflops", type=float, default=100.0, help="assumed sustained TFLOP/s")
    parser.add_argument("--measure-cpu", action="store_true", help="also time training steps on this CPU")
    args = parser.parse_args()
    config = get_config(args.config)
    profile = get_profile(config.sim_profile)
    shape = (profile.n_range_bins, profile.n_doppler_bins)
    in_channels = config.window * profile.n_rx
    steps = frame_steps(config.name)
    per_seed = sum(steps.values())
    print(f"{config.name} config: {config.n_scenes} {config.sim_profile} scenes, maps {shape}, widths x{config.width_scale:g}, "
          f"{config.seeds} seeds; frame-steps per architecture and seed at the epoch ceilings: {steps} = {per_seed:,}")
    total_s = total_cpu_s = 0.0
    for name in config.models:
        flops = train_flops_per_frame(name, in_channels, shape, config.width_scale)
        seconds = per_seed * config.seeds * flops / (args.sustained_tflops * 1e12)
        total_s += seconds
        params = parameter_count(build_model(name, in_channels, config.width_scale))
        line = (f"{name:14s} {params:>12,} parameters  {flops / 1e9:8.2f} GFLOP per training frame  "
                f"{seconds / 3600:6.2f} h for {config.seeds} seeds at {args.sustained_tflops:g} TFLOP/s")
        if args.measure_cpu:
            cpu = measured_cpu_flops(name, in_channels, shape, config.width_scale, config.pretrain.batch_size)
            cpu_s = per_seed * config.seeds * flops / cpu
            total_cpu_s += cpu_s
            line += f"; this CPU ({torch.get_num_threads()} threads) {cpu / 1e9:.1f} GFLOP/s measured: {cpu_s / 3600:.1f} h"
        print(line, flush=True)
    print(f"all rows: {total_s / 3600:.2f} h on one GPU at {args.sustained_tflops:g} TFLOP/s sustained (projection)")
    if args.measure_cpu:
        print(f"all rows: {total_cpu_s / 3600:.1f} h on this CPU at its measured throughput (projection)")


if __name__ == "__main__":
    main()
