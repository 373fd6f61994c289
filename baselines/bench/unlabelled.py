"""``zendar-bench`` on a dataset without manual labels (an imported release): the steps that need none.

When no scene of the dataset carries manual labels, the bench runs what needs none, each step cached
as in a full run (:mod:`run_directory`):

1. automatic labels of the training split (and of the validation split, which then chooses the
   pretraining checkpoints), with their statistics (cells and cubes marked moving or uncertain per
   scene and radar) instead of their quality;
2. the CFAR baseline's predictions of the test split, with the chain's default constants (fitting
   them needs manual labels), in the leaderboard's submission format: the ``zendar-eval``
   predictions file with its ``meta`` filled in but for ``team`` and ``contact``;
3. each CNN's pretraining on the automatic labels, per seed.

Scoring, the supervised-only rows, fine-tuning and the paper's claims need manual labels: they are
skipped, and ``results.json`` (``skipped``) and ``table.md`` list each with the reason.

Each step leaves out the scenes without range-Doppler cubes and the radars whose maps are smaller than
the CFAR window (:func:`usable_scenes`); ``results.json`` (``skipped``) and ``table.md`` list each with
the reason, and a row whose split has no scene left is skipped with it.
"""

from __future__ import annotations

import platform
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from zendar_dataset.atomic_files import write_json_atomic, write_text_atomic
from zendar_dataset.cluster import connected
from zendar_dataset.detection import ChainParams
from zendar_dataset.errors import ZendarError
from zendar_dataset.format.reader import DatasetIndex
from zendar_dataset.worker_pool import usable_cpus

from zendar_baselines.bench.context import RowSeed, RunContext
from zendar_baselines.bench.results_table import METHOD_NAMES
from zendar_baselines.bench.run import say, step_times_s
from zendar_baselines.bench.run_directory import RunDirectory, read_json
from zendar_baselines.classical.cfar_baseline import cfar_misfits

NO_LABELS = "the dataset has no manual labels"
STATISTICS_FILE = "statistics.json"
PREDICTIONS_FILE = "predictions.json"
#: What a submission's meta needs that only its submitter knows (docs/leaderboard.md, "Submissions").
SUBMITTER_FIELDS = ("team", "contact")
NO_CUBES = "no range-Doppler cubes (no radar streams)"
CFAR_STEP = "CFAR predictions"
TRAIN_STEP = "automatic labels and pretraining"
VAL_STEP = "automatic labels of the validation split"


def has_no_labels(index: DatasetIndex) -> bool:
    """Whether no scene of the dataset carries manual labels."""
    for scene_id in index.scene_ids():
        with index.open_scene(scene_id) as reader:
            if reader.labels() is not None:
                return False
    return True


# --- scenes and radars left out ------------------------------------------------------------------


@dataclass(frozen=True)
class LeftOut:
    """A scene, or one radar of it, that a step leaves out, and why.

    Attributes
    ----------
    step : str
        The step (:data:`CFAR_STEP`, :data:`TRAIN_STEP` or :data:`VAL_STEP`).
    scene_id : str
    radar : str or None
        None: the whole scene.
    reason : str
    """

    step: str
    scene_id: str
    radar: str | None
    reason: str

    @property
    def where(self) -> str:
        """``scene <id>``, or ``scene <id>, radar <name>``."""
        return f"scene {self.scene_id}" + ("" if self.radar is None else f", radar {self.radar}")

    def to_json(self) -> dict[str, str]:
        """Its entry of ``results.json``'s ``skipped``."""
        return {"what": f"{self.step}: {self.where}", "reason": self.reason}


def usable_scenes(dataset: DatasetIndex, scene_ids: list[str], step: str) -> tuple[list[str], list[LeftOut]]:
    """The scenes of ``scene_ids`` that ``step`` uses, and what it leaves out, each with why (said on stderr).

    ``step`` leaves out a scene without range-Doppler cubes and each radar whose maps the chain's CFAR
    window does not fit (:func:`cfar_misfits`); it uses the scenes with a radar left.
    """
    usable, left_out = [], []
    for scene_id in scene_ids:
        with dataset.open_scene(scene_id) as reader:
            radars, misfits = reader.sensors("radar"), cfar_misfits(reader)
        if not radars:
            left_out.append(LeftOut(step, scene_id, None, NO_CUBES))
        left_out += [LeftOut(step, scene_id, radar, reason) for radar, reason in misfits.items()]
        if len(misfits) < len(radars):
            usable.append(scene_id)
    for part in left_out:
        say(f"[{step}] leaving out {part.where}: {part.reason}")
    return usable, left_out


def _all_left_out(split: str, left_out: list[LeftOut]) -> str:
    """A row's reason when every scene of ``split`` is left out: the distinct reasons."""
    return f"every scene of split {split!r} is left out: " + "; ".join(dict.fromkeys(part.reason for part in left_out))


# --- automatic labels ----------------------------------------------------------------------------


def write_auto_labels_with_statistics(dataset: DatasetIndex, scene_ids: list[str], step_dir: Path,
                                      scheduler: str | None = None) -> None:
    """Automatic masks of ``scene_ids`` (a store in ``step_dir / "store"``; one task per scene on the Dask
    cluster of ``scheduler`` when given) and :data:`STATISTICS_FILE`."""
    from zendar_baselines.bench.autolabels import write_auto_labels
    from zendar_baselines.bench.steps import STORE_DIR

    with connected(scheduler) as cluster:
        write_auto_labels(dataset, scene_ids, step_dir, quality=False, cluster=cluster)
    write_json_atomic(step_dir / STATISTICS_FILE, label_statistics(step_dir / STORE_DIR, dataset))


def label_statistics(store_dir: Path, dataset: DatasetIndex) -> dict[str, Any]:
    """Cubes and cells of each class in a mask store, per scene and radar and in all.

    Returns
    -------
    dict
        ``{"all": counts, "scenes": {scene: {radar: counts}}}``, counts being ``cubes``,
        ``cubes_with_moving`` and ``cells``, ``moving_cells``, ``uncertain_cells``.
    """
    from zendar_baselines.labels.mask_classes import MOVING, UNCERTAIN
    from zendar_baselines.labels.mask_store import MaskStore

    store = MaskStore.open(store_dir, dataset)
    scenes: dict[str, dict[str, dict[str, int]]] = {}
    keys = ("cubes", "cubes_with_moving", "cells", "moving_cells", "uncertain_cells")
    total = dict.fromkeys(keys, 0)
    for scene_id in store.scene_ids():
        scenes[scene_id] = {}
        for radar, (_, masks) in store.scene(scene_id).items():
            moving = masks == MOVING
            counts = {
                "cubes": int(masks.shape[0]),
                "cubes_with_moving": int(np.count_nonzero(moving.reshape(masks.shape[0], -1).any(axis=1))),
                "cells": int(masks.size),
                "moving_cells": int(np.count_nonzero(moving)),
                "uncertain_cells": int(np.count_nonzero(masks == UNCERTAIN)),
            }
            scenes[scene_id][radar] = counts
            total = {key: total[key] + counts[key] for key in keys}
    return {"all": total, "scenes": scenes}


def markdown_statistics(statistics: dict[str, Any]) -> str:
    """The statistics as a markdown table, one line per scene and radar and one for all."""

    def line(name: str, counts: dict[str, int]) -> str:
        cells = max(counts["cells"], 1)
        return (f"| {name} | {counts['cubes']} | {counts['cubes_with_moving']} | "
                f"{counts['moving_cells']} ({100 * counts['moving_cells'] / cells:.2f} %) | "
                f"{counts['uncertain_cells']} ({100 * counts['uncertain_cells'] / cells:.2f} %) |")

    lines = ["| scene / radar | cubes | cubes with a moving cell | moving cells | uncertain cells |", "|---|--:|--:|--:|--:|"]
    lines += [line(f"{scene} / {radar}", counts) for scene, radars in statistics["scenes"].items() for radar, counts in radars.items()]
    lines.append(line("all", statistics["all"]))
    return "\n".join(lines) + "\n"


# --- CFAR predictions ----------------------------------------------------------------------------


def write_cfar_submission(context: RunContext, step_dir: Path, scheduler: str | None = None) -> None:
    """The CFAR baseline's predictions of the test split, with the chain's default constants, as a
    leaderboard submission but for :data:`SUBMITTER_FIELDS` (``step_dir / predictions.json``); one task
    per scene on the Dask cluster of ``scheduler`` when given."""
    from zendar_baselines.bench.scoring import cfar_predictions

    params = ChainParams()
    started = time.perf_counter()
    with connected(scheduler) as cluster:
        predictions = cfar_predictions(context.dataset, params, cluster=cluster)
    elapsed_s = time.perf_counter() - started
    n_frames = len(predictions["results"])
    predictions["meta"].update({
        "description": "CA-CFAR peaks of each radar's latest cube, DOA, the SAR static-scene test, DBSCAN clusters "
                       "(paper Table 1, row 1). The chain's constants are the package's defaults, not fitted: "
                       f"{NO_LABELS}.",
        "uses_unsupervised_pretraining": False,
        "uses_supervised": False,
        "uses_sar": True,
        "uses_camera": False,
        "uses_lidar": False,
        "external_data": False,
        "runtime_ms": round(1000.0 * elapsed_s / max(n_frames, 1), 3),
        "hardware": f"{platform.machine() or 'unknown machine'}, {usable_cpus()} CPU cores",
        "chain_fit": {"fitted": False, "reason": NO_LABELS},
    })
    write_json_atomic(step_dir / PREDICTIONS_FILE, predictions)


# --- pretraining ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class AutoLabelled:
    """A step's automatic labels: its directory and the scenes it labelled."""

    directory: Path
    scene_ids: list[str]


def pretrain_seed(context: RunContext, training: AutoLabelled, validation_labels: AutoLabelled | None, row: RowSeed,
                  out_dir: Path) -> None:
    """One seed of one CNN's pretraining on the training scenes' automatic labels (``config.pretrain``).

    The checkpoint is the epoch of least loss on the validation scenes' automatic labels, or without
    them on the last :data:`~zendar_baselines.bench.steps.HOLD_OUT_FRACTION` of each training scene's
    frames, held out. ``checkpoint.json`` and ``curves.json`` as a full run's.
    """
    from zendar_baselines.bench.steps import HOLD_OUT_FRACTION, STORE_DIR, _every_kth, _frames, write_training_records
    from zendar_baselines.cnn.models import build_model, parameter_count
    from zendar_baselines.cnn.training import hold_out_tail, seed_everything, train

    config, window = context.config, context.config.window
    train_ids = training.scene_ids
    everything = _frames(context, train_ids, training.directory / STORE_DIR)
    in_channels = everything.datasets[0].in_channels
    if validation_labels is not None:
        val_ids = validation_labels.scene_ids
        validation = _every_kth(_frames(context, val_ids, validation_labels.directory / STORE_DIR), window)
        record = {"source": "val split, automatic labels", "scenes": val_ids, "window_stride": window,
                  "n_samples": len(validation)}
    else:
        everything, held_out = hold_out_tail(everything, HOLD_OUT_FRACTION, gap=window - 1)
        validation = _every_kth(held_out, window)
        record = {"source": "held-out automatically labelled training frames", "scenes": train_ids,
                  "fraction": HOLD_OUT_FRACTION, "window_stride": window, "n_samples": len(validation)}
    seed_everything(row.seed)
    model = build_model(row.model_name, in_channels, config.width_scale).to(context.device)
    result = train(model, everything, config.pretrain, seed=row.seed, out_dir=out_dir / "pretrain", device=context.device,
                   validation=validation, progress=context.progress,
                   description=f"{row.model_name} pretrain seed {row.seed} ({parameter_count(model):,} parameters)")
    write_training_records(out_dir, row, {"pretrain": result}, record)


# --- the run -------------------------------------------------------------------------------------


def run_unlabelled_bench(context: RunContext, seeds: int, scheduler: str | None = None) -> dict[str, Any]:
    """Every step of the module docstring on ``context``'s dataset (reusing finished ones; the automatic
    labels and CFAR predictions one task per scene on the Dask cluster of ``scheduler`` when given);
    writes ``results.json`` and ``table.md`` and returns the former's content."""
    started = time.monotonic()
    dataset, config = context.dataset, context.config
    train_ids, val_ids, test_ids = (dataset.scene_ids(split) for split in ("train", "val", "test"))
    if not train_ids and not test_ids:
        raise ZendarError(f"{context.root}: splits 'train' and 'test' have no scenes; nothing to label or predict")
    say(f"[labels] {NO_LABELS}: only the steps that need none run (automatic labels, CFAR predictions, pretraining)")
    run = RunDirectory(context.run_path, {"config": config.name, "dataset": context.fingerprint})
    base_inputs = context.step_inputs()
    rows: list[dict[str, Any]] = []
    statistics = None
    usable_test, left_out_test = usable_scenes(dataset, test_ids, CFAR_STEP)
    usable_train, left_out_train = usable_scenes(dataset, train_ids, TRAIN_STEP)
    usable_val, left_out_val = usable_scenes(dataset, val_ids, VAL_STEP)

    if usable_test:
        # A submission predicts every test frame: those of left-out scenes and radars have no detections.
        cfar_dir, _, _ = run.step("rows/cfar", base_inputs, lambda d: write_cfar_submission(context, d, scheduler))
        n_frames = len(read_json(cfar_dir / PREDICTIONS_FILE)["results"])
        rows.append(_row("cfar", False, False, done=f"predictions of the {n_frames} test frames",
                         predictions=f"rows/cfar/{PREDICTIONS_FILE}", skipped="scoring", reason=NO_LABELS))
    else:
        reason = _all_left_out("test", left_out_test) if test_ids else "split 'test' has no scenes"
        rows.append(_row("cfar", False, False, skipped="predictions and scoring", reason=reason))

    training = validation_labels = None
    if usable_train:
        auto_dir, auto_key, _ = run.step("autolabels", {**base_inputs, "scenes": usable_train},
                                         lambda d: write_auto_labels_with_statistics(dataset, usable_train, d, scheduler))
        training = AutoLabelled(auto_dir, usable_train)
        statistics = read_json(auto_dir / STATISTICS_FILE)
        say("[autolabels] statistics of the training split's automatic labels:\n" + markdown_statistics(statistics))
        validation_key = None
        if usable_val:
            validation_dir, validation_key, _ = run.step(
                "autolabels_val", {**base_inputs, "scenes": usable_val},
                lambda d: write_auto_labels_with_statistics(dataset, usable_val, d, scheduler))
            validation_labels = AutoLabelled(validation_dir, usable_val)
    for model_name in config.models:
        rows.append(_row(f"{model_name}-supervised", False, True, skipped="training and scoring",
                         reason=f"{NO_LABELS} to train on"))
        key = RowSeed(model_name, True, 0).row_key
        if training is None:
            reason = _all_left_out("train", left_out_train) if train_ids else "split 'train' has no scenes"
            rows.append(_row(key, True, True, skipped="pretraining, fine-tuning and scoring", reason=reason))
            continue
        for seed in range(seeds):
            row = RowSeed(model_name, True, seed)
            inputs = {**base_inputs, "autolabels": auto_key, "validation": validation_key, "model": model_name, "seed": seed}
            run.step(f"rows/{key}/seed-{seed}", inputs,
                     lambda d, r=row: pretrain_seed(context, training, validation_labels, r, d))
        rows.append(_row(key, True, True, done=f"pretraining on the automatic labels, {seeds} seed(s)",
                         checkpoints=[f"rows/{key}/seed-{seed}/checkpoint.json" for seed in range(seeds)],
                         skipped="fine-tuning and scoring", reason=NO_LABELS))
    left_out = left_out_test + left_out_train + left_out_val
    return _write_outputs(context, seeds, rows, left_out, statistics, time.monotonic() - started)


def _row(key: str, unsupervised: bool, supervised: bool, *, skipped: str, reason: str, done: str | None = None,
         **files: Any) -> dict[str, Any]:
    """A row's entry of ``results.json``: what was done, what was skipped and why."""
    method = METHOD_NAMES[key.rsplit("-", 1)[0] if key != "cfar" else key]
    return {"key": key, "method": method, "unsupervised": unsupervised, "supervised": supervised,
            "done": done, "skipped": skipped, "reason": reason, **files}


def _write_outputs(context: RunContext, seeds: int, rows: list[dict[str, Any]], left_out: list[LeftOut],
                   statistics: dict[str, Any] | None, elapsed_s: float) -> dict[str, Any]:
    config, out = context.config, context.run_path
    claims_reason = f"they compare the rows' scores, and no row is scored: {NO_LABELS}"
    results = {
        "format": "zendar-bench-results",
        "format_version": 1,
        "manual_labels": False,
        "config": config.to_json(),
        "seeds": seeds,
        "device": context.device,
        "code_version": context.code_version,
        "dataset": {"root": str(context.root), "fingerprint": context.fingerprint},
        "rows": rows,
        "skipped": [{"what": f"{row['key']}: {row['skipped']}", "reason": row["reason"]} for row in rows]
                   + [{"what": "the paper's claims", "reason": claims_reason}] + [part.to_json() for part in left_out],
        "claims": {"skipped": True, "reason": claims_reason},
        "submission": {"predictions": f"rows/cfar/{PREDICTIONS_FILE}", "add_to_meta": list(SUBMITTER_FIELDS)}
                      if any(row.get("predictions") for row in rows) else None,
        "autolabel_statistics": statistics,
        "elapsed_s": round(elapsed_s, 1),
        "step_elapsed_s": step_times_s(out),
    }
    lines = [f"### zendar-bench on {context.root}, config {config.name}, {seeds} seed(s): {NO_LABELS}", "",
             "Only the steps that need no manual labels ran; nothing is scored.", "",
             "| row | done | skipped | why |", "|---|---|---|---|"]
    for row in rows:
        kind = "" if row["key"] == "cfar" else (" pretrained + fine-tuned" if row["unsupervised"] else " supervised-only")
        done = row["done"] or "-"
        for name in ("predictions", "checkpoints"):
            if row.get(name):
                done += f" ({', '.join(row[name]) if isinstance(row[name], list) else row[name]})"
        lines.append(f"| {row['method']}{kind} | {done} | {row['skipped']} | {row['reason']} |")
    lines.append(f"| the paper's claims | - | all | {claims_reason} |")
    if left_out:
        lines += ["", "### Scenes and radars left out", "", "| step | left out | why |", "|---|---|---|"]
        lines += [f"| {part.step} | {part.where} | {part.reason} |" for part in left_out]
    if results["submission"] is not None:
        lines += ["", f"`rows/cfar/{PREDICTIONS_FILE}` is a leaderboard submission once `meta.team` and `meta.contact` "
                      "are added (docs/leaderboard.md, \"Submissions\")."]
    if statistics is not None:
        lines += ["", "### Automatic labels of the training split", "", markdown_statistics(statistics).rstrip()]
    table = "\n".join(lines) + "\n"
    write_json_atomic(out / "results.json", results)
    write_text_atomic(out / "table.md", table)
    say(table)
    return results
