"""``zendar-bench``: Table 1 of the paper, end to end, resumable.

The steps, each cached in the run directory under a key of its inputs (:mod:`run_directory`):

1. the dataset: ``--data`` or one simulated into the cache (``$XDG_CACHE_HOME/zendar-dataset/bench``);
2. the semi-supervised split of the training scenes (``split.json``, checksummed);
3. automatic labels of every training scene (a side store beside, never inside, the dataset) and
   their precision and recall against the manual labels, per band;
4. the manual-label masks of the labelled part only;
5. the CFAR baseline on the test split;
6. per architecture and seed: supervised-only training, pretraining on automatic labels then
   fine-tuning; each scored on the test split;
7. ``results.json``, ``table.md``, ``table.csv``, precision-recall plots and a bird's-eye figure.
"""

from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any


from zendar_dataset.atomic_files import write_json_atomic
from zendar_dataset.errors import ZendarError
from zendar_dataset.eval import evaluate
from zendar_dataset.eval.report import read_metrics, write_metrics
from zendar_dataset.format.reader import open_dataset

from zendar_baselines.code_version import code_version
from zendar_baselines.configs import BenchConfig
from zendar_baselines.fingerprints import dataset_fingerprint
from zendar_baselines.results_table import METHOD_NAMES, Row, claims, csv_table, markdown_table
from zendar_baselines.run_directory import RunDirectory, read_json

if TYPE_CHECKING:
    from zendar_baselines.pipeline import ScoringScenes

#: Bootstrap resamples (over test scenes) for each row's 95 % interval.
BOOTSTRAP_RESAMPLES = 200


@dataclass(frozen=True)
class BenchOptions:
    """What the command line asked for.

    Attributes
    ----------
    config : BenchConfig
    data : Path or None
        ``--data``: the dataset (simulated there when absent); None for the cache.
    out : Path
        ``--out``.
    seeds : int
        Training seeds per CNN row.
    device : str
        ``cpu`` or ``cuda``.
    """

    config: BenchConfig
    data: Path | None
    out: Path
    seeds: int
    device: str


def cache_root() -> Path:
    """``$XDG_CACHE_HOME/zendar-dataset/bench`` (``~/.cache/...`` when the variable is unset)."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "zendar-dataset" / "bench"


def default_data_dir(config: BenchConfig) -> Path:
    """Where the simulated dataset of a configuration is cached."""
    return cache_root() / f"{config.sim_profile}-{config.n_scenes}scenes-seed{config.sim_seed}"


def say(text: str) -> None:
    """A step header on stderr, beside the progress bars."""
    print(text, file=sys.stderr, flush=True)


def ensure_dataset(options: BenchOptions) -> Path:
    """The dataset to run on: simulated (resumably) when absent; checked to have labels where needed."""
    from zendar_dataset.sim.generate import synthesize_dataset

    config = options.config
    root = options.data if options.data is not None else default_data_dir(config)
    if not (root / "dataset.json").is_file():
        # The simulator resumes its own interrupted run there and refuses a directory of other files.
        say(f"[data] simulating the {config.sim_profile} dataset ({config.n_scenes} scenes) into {root}")
        synthesize_dataset(root, profile=config.sim_profile, n_scenes=config.n_scenes, seed=config.sim_seed,
                           progress=True, jobs=synthesis_jobs(config.n_scenes))
    index = open_dataset(str(root))
    problems = []
    for split in ("train", "test"):
        if not index.scene_ids(split):
            problems.append(f"split {split!r} has no scenes")
    for scene_id in index.scene_ids("train") + index.scene_ids("test"):
        if index.open_scene(scene_id).labels() is None:
            problems.append(f"scene {scene_id} has no labels (the bench trains on the train split's and scores the test split's)")
    if problems:
        raise ZendarError(f"{root}: cannot run the benchmark on this dataset:\n  " + "\n  ".join(problems))
    return root


def synthesis_jobs(n_scenes: int) -> int:
    """Worker processes for simulating: the usable CPUs, one per scene at most."""
    from zendar_dataset.sim.generate import usable_cpus

    return max(1, min(usable_cpus(), n_scenes))


def run_bench(options: BenchOptions) -> dict[str, Any]:
    """Run every step (reusing finished ones) and write the outputs; returns ``results.json``'s content."""
    started = time.monotonic()
    config = options.config
    RunDirectory.check_owner(options.out, {"config": config.name})
    root = ensure_dataset(options)
    identity = {"config": config.name, "dataset": dataset_fingerprint(root)}
    run = RunDirectory(options.out, identity)
    base_inputs = {"config": config.to_json(), "dataset": identity["dataset"], "code_version": code_version()}

    from zendar_baselines import pipeline

    split_dir, split_key, _ = run.step("split", base_inputs, lambda d: pipeline.write_semi_supervised_split(root, config, d))
    split = pipeline.read_semi_supervised_split(split_dir, root)
    say(f"[split] {len(split.labelled)} labelled / {len(split.unlabelled)} unlabelled training scenes")

    auto_dir, auto_key, _ = run.step("autolabels", {**base_inputs, "split": split_key},
                                     lambda d: pipeline.write_auto_labels(root, [*split.labelled, *split.unlabelled], d))
    quality = read_json(auto_dir / "quality.json")
    say("[autolabels] quality against the manual labels of the training scenes:\n" + quality["table"])

    masks_dir, masks_key, _ = run.step("label_masks", {**base_inputs, "split": split_key},
                                       lambda d: pipeline.write_label_masks(root, split, d))

    rows: list[Row] = []
    cfar_dir, _, _ = run.step("rows/cfar", base_inputs, lambda d: _score_into(d, pipeline.cfar_predictions(root), root))
    rows.append(Row("cfar", METHOD_NAMES["cfar"], False, False, [read_metrics(cfar_dir / "metrics.json")]))

    with pipeline.ScoringScenes(root) as test_scenes:
        for model_name in config.models:
            for pretrained in (False, True):
                key = f"{model_name}-{'pretrained' if pretrained else 'supervised'}"
                row = Row(key, METHOD_NAMES[model_name], pretrained, True)
                for seed in range(options.seeds):
                    inputs = {**base_inputs, "split": split_key, "autolabels": auto_key, "label_masks": masks_key,
                              "model": model_name, "pretrained": pretrained, "seed": seed}
                    seed_dir, _, _ = run.step(
                        f"rows/{key}/seed-{seed}", inputs,
                        lambda d, s=seed, p=pretrained, m=model_name: _train_and_score(
                            d, root, config, split, auto_dir, masks_dir, m, p, s, options.device, run.path, test_scenes),
                    )
                    row.seed_metrics.append(read_metrics(seed_dir / "metrics.json"))
                _copy_first_seed(run.path / "rows" / key)
                rows.append(row)

    results = _write_outputs(run.path, root, config, options, rows, quality, time.monotonic() - started)
    return results


def _score_into(out_dir: Path, predictions: dict[str, Any], root: Path) -> None:
    write_json_atomic(out_dir / "predictions.json", predictions)
    metrics = evaluate(out_dir / "predictions.json", str(root), split="test", bootstrap=BOOTSTRAP_RESAMPLES)
    write_metrics(metrics, out_dir)


def _train_and_score(out_dir: Path, root: Path, config: BenchConfig, split, auto_dir: Path, masks_dir: Path,
                     model_name: str, pretrained: bool, seed: int, device: str, run_path: Path,
                     test_scenes: ScoringScenes) -> None:
    from zendar_baselines import pipeline

    checkpoint = pipeline.train_row(out_dir, root, config, split, auto_dir, masks_dir, run_path / "inputs", model_name,
                                    pretrained, seed, device)
    _score_into(out_dir, pipeline.cnn_predictions(root, config, checkpoint, device, scenes=test_scenes), root)


def _copy_first_seed(row_dir: Path) -> None:
    """``rows/<key>/{metrics,predictions}.json``: the first seed's, beside ``seed-<k>/``."""
    for name in ("metrics.json", "predictions.json"):
        write_json_atomic(row_dir / name, read_json(row_dir / "seed-0" / name))


def _write_outputs(out: Path, root: Path, config: BenchConfig, options: BenchOptions, rows: list[Row],
                   quality: dict[str, Any], elapsed_s: float) -> dict[str, Any]:
    from zendar_baselines import pipeline
    from zendar_baselines.figures import write_pr_comparisons

    title = f"Moving-car AP on the test split, config {config.name}, {options.seeds} seed(s) (paper Table 1 beside)"
    verdicts = claims(rows)
    results = {
        "format": "zendar-bench-results",
        "format_version": 1,
        "config": config.to_json(),
        "seeds": options.seeds,
        "device": options.device,
        "code_version": code_version(),
        "dataset": {"root": str(root), "fingerprint": dataset_fingerprint(root)},
        "rows": [row.to_json() for row in rows],
        "claims": verdicts,
        "autolabel_quality": quality["quality"],
        "elapsed_s": round(elapsed_s, 1),
    }
    write_json_atomic(out / "results.json", results)
    table = markdown_table(rows, title)
    table += "\n" + "\n".join(
        f"- {name.replace('_', ' ')}: {'holds' if v['holds'] else 'unknown' if v['holds'] is None else 'does not hold'}"
        + (f" ({'; '.join(v['failures'])})" if v["failures"] else "")
        for name, v in verdicts.items()
    ) + "\n"
    from zendar_dataset.atomic_files import write_text_atomic

    write_text_atomic(out / "table.md", table)
    write_text_atomic(out / "table.csv", csv_table(rows))
    write_json_atomic(out / "autolabel_quality.json", quality["quality"])
    curves = [(_label(row), row.seed_metrics[0]) for row in rows]
    write_pr_comparisons(curves, out)
    pipeline.write_bev_figure(out / "bev.png", root, {_label(row): out / "rows" / row.key / "predictions.json"
                                                      for row in rows})
    say(table)
    return results


def _label(row: Row) -> str:
    if not row.supervised:
        return row.method
    return f"{row.method} ({'pretrained + fine-tuned' if row.unsupervised else 'supervised only'})"
