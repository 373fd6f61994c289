"""Projected training time of a ``zendar-bench`` configuration, from counted work.

    python benchmarks/bench_paper_projection.py [--config paper|gpu|demo|tiny] [--sustained-tflops 100] [--measure-cpu]
    python benchmarks/bench_paper_projection.py --cluster --labels-data DIR [--cpu-nodes 8] [--cores-per-node 32]
        [--workers-per-node 4] [--gpus 4]

A projection, not a measurement. Per architecture it counts the floating-point operations of one
training step per frame at the configuration's map size and widths with ``torch.utils.flop_counter``
(forward + backward; convolutions and matrix products, which dominate), counts the frame-steps of
the configuration at its epoch ceilings (pretraining on every training cube's automatic labels,
fine-tuning and supervised-only training on the labelled part, for every seed; one window per cube,
the first ones padded; early stopping only shortens this), and divides by a sustained throughput.
The default 100 TFLOP/s is about 20 % of an H100/H200's dense TF32 peak (495 TFLOP/s), typical of
convolution training in float32 with TF32 enabled; pass another figure to rescale. With
``--measure-cpu`` it also times a few training steps of each architecture on this machine's CPU and
projects the same work at that measured throughput.

With ``--cluster`` it projects the whole configuration's wall time on a stated cluster
(``--cpu-nodes`` × ``--cores-per-node`` for the per-scene work, ``--workers-per-node`` Dask workers
each, and ``--gpus`` GPUs for training under torchrun) from measured per-scene and per-step costs:

- simulation: the core-hours of a 30 s ``paper`` scene measured on this package
  (``zendar_baselines.bench.paper_guard.PAPER_SCENE_CORE_HOURS_PER_30_S``), one scene per Dask
  worker at a time, its numba threads taken as scaling linearly over the worker's cores (the
  backprojection kernel measured 2.02× on 2 threads, benchmarks/bench_sar.py);
- automatic labels (training split), one scene per worker, one thread: seconds per cube of the
  CFAR, DOA and SAR-test chain with the masks' segments, measured here on a short
  ``paper`` scene given with ``--labels-data`` (``zendar-data synth DIR --profile paper --scenes 1
  --duration-s 0.5 --split-ratios 1,0,0``);
- training: the counted FLOPs above over ``--gpus`` GPUs at ``--sustained-tflops`` each, DDP taken
  as scaling linearly (optimistic: the paper's global batch of 8 leaves 2 frames per GPU on 4);
- the CFAR row's chain fit and scoring run in one process; each CNN seed's are shared by the
  torchrun ranks (every ``--gpus``-th scene each), at the same cost per cube (a CNN's peaks are taken
  as many as CFAR's; the model's inference is left out).
"""

from __future__ import annotations

import argparse
import math
import time

import torch
import torch.nn.functional as F
from torch.utils.flop_counter import FlopCounterMode

from zendar_dataset.format.reader import open_dataset
from zendar_dataset.sar.frames import SarFrames
from zendar_dataset.sim.profiles import get_profile

from zendar_baselines.bench.configs import get_config
from zendar_baselines.bench.paper_guard import PAPER_SCENE_CORE_HOURS_PER_30_S
from zendar_baselines.cnn.models import build_model, parameter_count
from zendar_baselines.labels.masks import scene_masks


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


def chain_seconds_per_cube(root: str) -> tuple[float, int, float]:
    """``(seconds per cube, cubes, seconds of scene)``: the automatic labels of every cube of a dataset's
    scenes (SAR frames opened per scene, included), timed in this process."""
    index = open_dataset(root)
    elapsed_s, cubes, duration_s = 0.0, 0, 0.0
    for scene_id in index.scene_ids():
        with index.open_scene(scene_id) as reader:
            started = time.perf_counter()
            sar = SarFrames(reader)
            for radar in reader.sensors("radar"):
                timestamps, _ = scene_masks(reader, radar, "auto", sar=sar, progress=False)
                cubes += timestamps.size
            elapsed_s += time.perf_counter() - started
            stamps = reader.timestamps(f"radar/{reader.sensors('radar')[0]}")
            duration_s += (int(stamps[-1]) - int(stamps[0])) / 1e9 + 1.0 / get_profile("paper").radar_rate_hz
    return elapsed_s / cubes, cubes, duration_s


def cluster_projection(args: argparse.Namespace, config, profile, training_s_one_gpu: float) -> None:
    """Print the configuration's projected wall time on the stated cluster (module docstring)."""
    per_cube_s, measured_cubes, measured_s = chain_seconds_per_cube(args.labels_data)
    cubes_per_scene = measured_cubes / measured_s * profile.scene_duration_s
    n_train = round(config.n_scenes * 0.6)
    # The chain fit reads the labelled segments and the validation split; scoring the test split.
    n_fit_and_score = round(config.labelled_fraction * n_train) + 2 * round(config.n_scenes * 0.2)
    n_seeds = 2 * len(config.models) * config.seeds
    workers = args.cpu_nodes * args.workers_per_node
    threads = max(1, args.cores_per_node // args.workers_per_node)
    scene_core_h = PAPER_SCENE_CORE_HOURS_PER_30_S * profile.scene_duration_s / 30.0
    scene_label_h = cubes_per_scene * per_cube_s / 3600
    rows = [
        ("simulation", f"{config.n_scenes} scenes x {scene_core_h:.1f} core-h", f"{workers} workers x {threads} threads",
         math.ceil(config.n_scenes / workers) * scene_core_h / threads),
        ("automatic labels", f"{n_train} scenes x {scene_label_h:.2f} h", f"{workers} workers",
         math.ceil(n_train / workers) * scene_label_h),
        ("CFAR chain fit and scoring", f"~{n_fit_and_score} scenes x {scene_label_h:.2f} h", "1 process",
         n_fit_and_score * scene_label_h),
        ("CNN training, every row and seed", f"{training_s_one_gpu / 3600:.1f} GPU-h at {args.sustained_tflops:g} TFLOP/s",
         f"{args.gpus} GPUs (torchrun, DDP)", training_s_one_gpu / args.gpus / 3600),
        ("each CNN seed's chain fit and scoring (its own peaks)",
         f"{n_seeds} seeds x ~{n_fit_and_score} scenes x {scene_label_h:.2f} h", f"{args.gpus} ranks sharing the scenes",
         n_seeds * math.ceil(n_fit_and_score / args.gpus) * scene_label_h),
    ]
    print(f"\nprojected wall time of --config {config.name} on {args.cpu_nodes} CPU nodes x {args.cores_per_node} cores "
          f"({args.workers_per_node} Dask workers each) and {args.gpus} GPUs; chain measured here: {per_cube_s * 1e3:.0f} ms "
          f"per cube over {measured_cubes} cubes of {args.labels_data} ({cubes_per_scene:.0f} cubes per "
          f"{profile.scene_duration_s:g} s scene)")
    print("| step | work | on | wall time (h) |")
    print("|---|---|---|--:|")
    for step, work, where, hours in rows:
        print(f"| {step} | {work} | {where} | {hours:.2f} |")
    print(f"| **total** (steps one after another) | | | **{sum(row[3] for row in rows):.2f}** |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", default="paper", help="the zendar-bench configuration (default: paper)")
    parser.add_argument("--sustained-tflops", type=float, default=100.0, help="assumed sustained TFLOP/s")
    parser.add_argument("--measure-cpu", action="store_true", help="also time training steps on this CPU")
    parser.add_argument("--cluster", action="store_true", help="also project the whole run's wall time on a cluster")
    parser.add_argument("--labels-data", help="--cluster: a short paper dataset to time the chain per cube on")
    parser.add_argument("--cpu-nodes", type=int, default=8)
    parser.add_argument("--cores-per-node", type=int, default=32)
    parser.add_argument("--workers-per-node", type=int, default=4)
    parser.add_argument("--gpus", type=int, default=4)
    args = parser.parse_args()
    if args.cluster and not args.labels_data:
        parser.error("--cluster needs --labels-data DIR (a short paper scene: see the module docstring)")
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
    if args.cluster:
        cluster_projection(args, config, profile, total_s)


if __name__ == "__main__":
    main()
