"""Projected wall time of ``zendar-bench --config paper`` on one GPU, from counted work.

    python benchmarks/bench_paper_projection.py [--sustained-tflops 100]

A projection, not a measurement: no GPU has been available to this project. Per architecture it
counts the floating-point operations of one training step per frame at the paper size (12 channels
of 512 x 256, published widths) with ``torch.utils.flop_counter`` (forward + backward; convolutions
and matrix products, which dominate), counts the frame-steps of the paper configuration (pretraining
on every training scene's automatic labels, fine-tuning and supervised-only training on the labelled
part, for every seed), and divides by a sustained throughput. The default 100 TFLOP/s is about 20 %
of an H100/H200's dense TF32 peak (495 TFLOP/s), typical of convolution training in float32 with
TF32 enabled; pass another figure to rescale. Simulation and the CFAR steps are left out.
"""

from __future__ import annotations

import argparse

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
    """Frame-steps per seed of one architecture: pretraining, fine-tuning and supervised-only."""
    config = get_config(config_name)
    profile = get_profile(config.sim_profile)
    n_train = round(config.n_scenes * 0.6)  # the simulator's default split ratios
    n_labelled = max(1, min(n_train - 1, int(config.labelled_fraction * n_train + 0.5)))
    cubes = int(profile.scene_duration_s * profile.radar_rate_hz)
    windows = 2 * (cubes - config.window + 1)  # two radars per scene
    return {
        "pretrain": n_train * windows * config.pretrain.epochs,
        "finetune": n_labelled * windows * config.finetune.epochs,
        "supervised": n_labelled * windows * config.supervised.epochs,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sustained-tflops", type=float, default=100.0, help="assumed sustained TFLOP/s")
    args = parser.parse_args()
    config = get_config("paper")
    profile = get_profile("paper")
    shape = (profile.n_range_bins, profile.n_doppler_bins)
    in_channels = config.window * profile.n_rx
    steps = frame_steps("paper")
    per_seed = sum(steps.values())
    print(f"paper config: {config.n_scenes} scenes, {config.seeds} seeds, frame-steps per architecture and seed: "
          f"{steps} = {per_seed:,}")
    total_s = 0.0
    for name in config.models:
        flops = train_flops_per_frame(name, in_channels, shape, config.width_scale)
        seconds = per_seed * config.seeds * flops / (args.sustained_tflops * 1e12)
        total_s += seconds
        params = parameter_count(build_model(name, in_channels, config.width_scale))
        print(f"{name:14s} {params:>12,} parameters  {flops / 1e9:8.1f} GFLOP per training frame  "
              f"{seconds / 3600:6.2f} h for {config.seeds} seeds at {args.sustained_tflops:g} TFLOP/s")
    print(f"all rows: {total_s / 3600:.1f} h on one GPU at {args.sustained_tflops:g} TFLOP/s sustained (projection)")


if __name__ == "__main__":
    main()
