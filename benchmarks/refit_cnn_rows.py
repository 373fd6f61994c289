"""Re-fit the chain of every CNN row and seed of a finished ``zendar-bench`` run with the current code, and
score the test split again; then the paired claims on the re-scored seeds.

    python benchmarks/refit_cnn_rows.py RUN_OUT DATASET WORK [--config demo]

``RUN_OUT`` is the run's ``--out`` (its checkpoints and ``split/split.json`` are read, nothing in it is
written), ``DATASET`` its dataset, ``WORK`` a new folder for the re-fitted ``chain_fit.json`` and
``predictions.json`` of each row and seed. Training is deterministic, so a run's checkpoints are what a
fresh run of the same training code would make: this measures a change of the chain fit (how the
CNN rows' SAR threshold is chosen) without training again. Prints, per row and seed, the fitted
threshold and radius and the test AP, re-fitted and as the run recorded it; per row the mean ± std
over seeds; and the claims table.
"""

from __future__ import annotations

import argparse
import json
import shutil
import statistics
from pathlib import Path

from zendar_baselines.bench import chain_step, scoring, steps
from zendar_baselines.bench.claims import (
    claim_verdicts,
    markdown_claims,
    matched_seeds,
)
from zendar_baselines.bench.configs import get_config
from zendar_baselines.bench.context import RunContext
from zendar_baselines.bench.results_table import METHOD_NAMES, Row
from zendar_baselines.labels.splits import read_split

from zendar_dataset.eval import evaluate

BANDS = ("near", "mid", "far", "all")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run_out", type=Path)
    parser.add_argument("dataset", type=Path)
    parser.add_argument("work", type=Path)
    parser.add_argument("--config", default="demo")
    args = parser.parse_args()
    context = RunContext.open(args.dataset, get_config(args.config), args.work, "cpu")
    split = read_split(args.run_out / "split" / "split.json", dataset_root=context.dataset)
    seeds = json.loads((args.run_out / "results.json").read_text())["seeds"]  # this run's, not leftover folders
    rows = [Row("cfar", METHOD_NAMES["cfar"], False, False)]
    (args.work / "rows" / "cfar").mkdir(parents=True, exist_ok=True)
    shutil.copy(args.run_out / "rows" / "cfar" / "predictions.json", args.work / "rows" / "cfar" / "predictions.json")
    with scoring.ScoringScenes(context.dataset) as scenes:
        for model in context.config.models:
            for pretrained in (False, True):
                key = f"{model}-{'pretrained' if pretrained else 'supervised'}"
                rows.append(Row(key, METHOD_NAMES[model], pretrained, True))
                refitted, recorded = [], []
                for seed_dir in (args.run_out / "rows" / key / f"seed-{k}" for k in range(seeds)):
                    out = args.work / "rows" / key / seed_dir.name
                    out.mkdir(parents=True, exist_ok=True)
                    checkpoint = steps.final_checkpoint(seed_dir)
                    params, summary = chain_step.write_cnn_chain_fit(context, split, checkpoint, key, out)
                    predictions = scoring.cnn_predictions(context.dataset, context.config, checkpoint, "cpu", params=params,
                                                          scenes=scenes, chain_fit=summary)
                    (out / "predictions.json").write_text(json.dumps(predictions))
                    refitted.append(evaluate(out / "predictions.json", str(args.dataset), split="test")["ap"])
                    recorded.append(json.loads((seed_dir / "metrics.json").read_text())["ap"])
                    print(f"{key} {seed_dir.name}: threshold {params.sar.threshold_db} dB, radius {params.cluster_eps_m} m; "
                          f"AP all {refitted[-1]['all']:.3f} (recorded {recorded[-1]['all']:.3f})", flush=True)
                shutil.copy(args.work / "rows" / key / "seed-0" / "predictions.json", args.work / "rows" / key / "predictions.json")
                for name, runs in (("re-fitted", refitted), ("recorded", recorded)):
                    cells = [f"{100 * statistics.mean(r[b] for r in runs):.1f} ± {100 * statistics.stdev(r[b] for r in runs):.1f}"
                             if len(runs) > 1 else f"{100 * runs[0][b]:.1f}" for b in BANDS]
                    print(f"  {key} {name}: " + " / ".join(cells) + " (near / mid / far / all)")
    print(markdown_claims(claim_verdicts(rows, matched_seeds(args.work, rows, args.dataset, seeds))))


if __name__ == "__main__":
    main()
