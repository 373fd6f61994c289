"""Claim: with the demo / tiny schedules every CNN phase's validation loss flattens before its epoch
ceiling (docs/baselines.md, Configurations); it prints each phase's losses per epoch and the time a
row takes, from which the bench's training time is projected.

Run: python benchmarks/bench_training_curves.py DATASET --config demo [--models densenet-37]
         [--rows supervised,pretrained] [--pretrain LR,BATCH,EPOCHS,PATIENCE] [--finetune ...]
         [--supervised ...] [--threads 2] [--out /tmp/curves]

Inputs: ``DATASET`` (e.g. ``zendar-data synth /tmp/demo --profile demo``), the config's split,
automatic labels, manual-label and validation masks (bench steps, cached under ``--out``), then
``steps.train_row`` for seed 0 of each row asked, with the config's schedules unless overridden
(``none`` for no patience). Prints one JSON line per row: wall and CPU seconds of its training,
and per phase the epoch chosen, the epochs run, the train and validation losses per epoch.
``--threads`` replaces ``TRAINING_THREADS`` (1 on a machine shared with other jobs: CPU seconds
then measure the work, and idle 2-core wall time is at most that).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from zendar_baselines.bench import steps  # noqa: E402
from zendar_baselines.bench.autolabels import write_auto_labels  # noqa: E402
from zendar_baselines.bench.configs import Schedule, get_config  # noqa: E402
from zendar_baselines.bench.context import RowSeed, RunContext, TrainingLabels  # noqa: E402
from zendar_baselines.bench.run_directory import RunDirectory  # noqa: E402
from zendar_baselines.cnn import training  # noqa: E402


def schedule(text: str) -> Schedule:
    lr, batch, epochs, patience = text.split(",")
    return Schedule(float(lr), int(batch), int(epochs), None if patience == "none" else int(patience))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("dataset", type=Path)
    parser.add_argument("--config", default="demo")
    parser.add_argument("--models", default="densenet-37")
    parser.add_argument("--rows", default="supervised,pretrained")
    for phase in ("pretrain", "finetune", "supervised"):
        parser.add_argument(f"--{phase}", type=schedule)
    parser.add_argument("--threads", type=int, default=training.TRAINING_THREADS)
    parser.add_argument("--out", type=Path, default=Path("/tmp/curves"))
    args = parser.parse_args()
    training.TRAINING_THREADS = args.threads

    base = get_config(args.config)
    config = dataclasses.replace(base, **{phase: getattr(args, phase) or getattr(base, phase)
                                          for phase in ("pretrain", "finetune", "supervised")})
    run_path = args.out / "run"
    context = RunContext.open(args.dataset, base, run_path, "cpu")
    run = RunDirectory(run_path, {"config": base.name, "dataset": context.fingerprint})
    inputs = context.step_inputs()
    split_dir, split_key, _ = run.step("split", inputs, lambda d: steps.write_semi_supervised_split(context, d))
    split = steps.read_semi_supervised_split(context, split_dir)
    auto_dir, _, _ = run.step("autolabels", {**inputs, "split": split_key}, lambda d: write_auto_labels(
        context.dataset, [*split.labelled, *split.unlabelled], d, quality=False))
    masks_dir, _, _ = run.step("label_masks", {**inputs, "split": split_key},
                               lambda d: steps.write_label_masks(context, split, d))
    validation_dir, _, _ = run.step("validation_masks", inputs, lambda d: steps.write_validation_masks(context, d))
    labels = TrainingLabels(split, auto_dir, masks_dir, validation_dir)
    context = dataclasses.replace(context, config=config)
    for model in args.models.split(","):
        for kind in args.rows.split(","):
            row = RowSeed(model, kind == "pretrained", 0)
            out_dir = args.out / "rows" / row.row_key
            wall, cpu = time.monotonic(), time.process_time()
            steps.train_row(context, labels, row, out_dir)
            wall, cpu = time.monotonic() - wall, time.process_time() - cpu
            record = json.loads((out_dir / steps.CHECKPOINT_RECORD).read_text())
            phases = {name: {"best_epoch": phase["best_epoch"], "epochs_run": phase["epochs_run"],
                             "train": [round(v, 4) for v in phase["train_losses"]],
                             "validation": [round(v, 4) for v in phase["validation_losses"]]}
                      for name, phase in record["phases"].items()}
            print(json.dumps({"row": row.row_key, "wall_s": round(wall, 1), "cpu_s": round(cpu, 1), "phases": phases}),
                  flush=True)


if __name__ == "__main__":
    main()
