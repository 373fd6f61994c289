"""Claim: what changes the weights a CPU trains to: the intra-op thread count and oneDNN's vector
instruction set do, ATen's vectorised kernels do not, in the NCHW layout and in the channels-last
layout training uses (docs/baselines.md, Reproducibility across machines).

Run: python benchmarks/bench_reproducibility.py [--model densenet-37] [--steps 3] [--layouts nchw,channels_last]

Each variant runs in a fresh interpreter (oneDNN and ATen read their instruction-set caps once, at
their first use): ``--steps`` Adam steps (lr 1e-3) of the model at width 0.125 on batches of 16
random 12 × 256 × 64 inputs with 1 % moving cells, the same seeds every time, under deterministic
algorithms, the weights and inputs in the layout given. It prints the SHA-256 of the weights and the
CPU seconds per step; variants with equal hashes trained to bit-identical weights.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

STEP_SCRIPT = """
import sys, time, torch
from zendar_baselines.cnn.models import build_model
from zendar_baselines.cnn.training import masked_bce, state_sha256
model_name, steps, threads, layout = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
memory_format = {"nchw": torch.contiguous_format, "channels_last": torch.channels_last}[layout]
torch.set_num_threads(threads)
torch.use_deterministic_algorithms(True, warn_only=True)
torch.manual_seed(0)
model = build_model(model_name, 12, 0.125).to(memory_format=memory_format)
optimizer = torch.optim.Adam(model.parameters(), lr=1e-3)
generator = torch.Generator().manual_seed(1)
started = time.process_time()
for _ in range(steps):
    inputs = torch.randn(16, 12, 256, 64, generator=generator).contiguous(memory_format=memory_format)
    masks = (torch.rand(16, 256, 64, generator=generator) < 0.01).to(torch.uint8)
    loss_sum, n_labelled = masked_bce(model(inputs), masks, 10.0)
    optimizer.zero_grad()
    (loss_sum / n_labelled).backward()
    optimizer.step()
print(state_sha256(model), f"{(time.process_time() - started) / steps:.2f}")
"""

# Name, intra-op threads, environment. The training module sets ONEDNN_MAX_CPU_ISA=AVX2 unless the
# environment sets it, so "ALL" (no cap) has to be asked for explicitly.
VARIANTS = (
    ("oneDNN uncapped, 1 thread", 1, {"ONEDNN_MAX_CPU_ISA": "ALL"}),
    ("oneDNN uncapped, 2 threads", 2, {"ONEDNN_MAX_CPU_ISA": "ALL"}),
    ("oneDNN capped at AVX2, 1 thread", 1, {"ONEDNN_MAX_CPU_ISA": "AVX2"}),
    ("ATen capped at AVX2, oneDNN uncapped, 1 thread", 1, {"ONEDNN_MAX_CPU_ISA": "ALL", "ATEN_CPU_CAPABILITY": "avx2"}),
    ("ATen and oneDNN capped at AVX2, 1 thread", 1, {"ONEDNN_MAX_CPU_ISA": "AVX2", "ATEN_CPU_CAPABILITY": "avx2"}),
)
LAYOUTS = ("nchw", "channels_last")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default="densenet-37")
    parser.add_argument("--steps", type=int, default=3)
    parser.add_argument("--layouts", type=lambda text: text.split(","), default=list(LAYOUTS),
                        help=f"comma-separated, of {', '.join(LAYOUTS)}")
    args = parser.parse_args()
    unknown = sorted(set(args.layouts) - set(LAYOUTS))
    if unknown:
        parser.error(f"--layouts: unknown {', '.join(unknown)}; choose from {', '.join(LAYOUTS)}")
    import torch

    print(f"torch {torch.__version__}, CPU capability {torch.backends.cpu.get_cpu_capability()}, load {os.getloadavg()}")
    for layout in args.layouts:
        for name, threads, environment in VARIANTS:
            inherited = {key: value for key, value in os.environ.items() if key not in ("ONEDNN_MAX_CPU_ISA", "ATEN_CPU_CAPABILITY")}
            env = {**inherited, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]), **environment}
            done = subprocess.run([sys.executable, "-W", "ignore", "-c", STEP_SCRIPT, args.model, str(args.steps), str(threads), layout],
                                  capture_output=True, text=True, env=env, check=True)
            sha256, cpu_s = done.stdout.split()
            print(f"{layout:13s} {name:48s} weights {sha256[:16]}  {cpu_s} CPU s/step")


if __name__ == "__main__":
    main()
