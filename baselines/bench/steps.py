"""The steps of ``zendar-bench`` (:mod:`zendar_baselines.bench.run`) before scoring, each writing into its
step directory: the semi-supervised split, the manual-label masks of the labelled part (the automatic
labels: :mod:`zendar_baselines.bench.autolabels`), and the training of one seed of one CNN row.

Data flow: the training scenes' cubes become normalised log-power maps (memory-mapped ``.npy`` files,
so the paper config never holds a split in memory); automatic masks of every training scene and
manual-label masks of the labelled part only are the targets (:mod:`zendar_baselines.bench.scoring`
puts the trained models to the test split).
"""

from __future__ import annotations

import dataclasses
import math
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from tqdm import tqdm

from zendar_dataset.atomic_files import write_json_atomic
from zendar_dataset.errors import ZendarError
from zendar_dataset.format.reader import SceneReader
from zendar_dataset.temporary_files import remove_temporary, temporary_sibling

from zendar_baselines.bench import ranks
from zendar_baselines.bench.context import RowSeed, RunContext, TrainingLabels
from zendar_baselines.bench.run_directory import read_json
from zendar_baselines.cnn.input_channels import InputChannels
from zendar_baselines.labels.mask_classes import UNCERTAIN
from zendar_baselines.labels.mask_store import MaskStore
from zendar_baselines.labels.masks import MaskParams, scene_masks
from zendar_baselines.labels.splits import SemiSupervisedSplit, make_split, read_split, write_split

if TYPE_CHECKING:
    from torch.utils.data import ConcatDataset

    from zendar_baselines.cnn.training import TrainResult

SPLIT_FILE = "split.json"
STORE_DIR = "store"
CHECKPOINT_RECORD = "checkpoint.json"
CURVES_FILE = "curves.json"
#: Without validation scenes: the share of each labelled scene's frames (its last ones) held out to
#: choose the checkpoint.
HOLD_OUT_FRACTION = 0.2


def mask_parameters(params: MaskParams | None = None) -> dict[str, Any]:
    """The mask settings as JSON (recorded in the stores)."""
    return dataclasses.asdict(MaskParams() if params is None else params)


# --- split ---------------------------------------------------------------------------------------


def write_semi_supervised_split(run: RunContext, step_dir: Path) -> None:
    """``split.json``: the training scenes' labelled segments (seeded by the config).

    Raises
    ------
    SplitError
        When the labelled part holds fewer than the config's ``min_labelled_cars`` distinct cars in a band.
    """
    split = make_split(run.dataset, run.config.labelled_fraction, seed=run.config.sim_seed,
                       min_cars_per_band=run.config.min_labelled_cars)
    write_split(split, step_dir / SPLIT_FILE, dataset_root=run.dataset)


def read_semi_supervised_split(run: RunContext, step_dir: Path) -> SemiSupervisedSplit:
    """The split written by :func:`write_semi_supervised_split`, checked against the dataset."""
    return read_split(step_dir / SPLIT_FILE, dataset_root=run.dataset)


# --- masks ---------------------------------------------------------------------------------------


def write_label_masks(run: RunContext, split: SemiSupervisedSplit, step_dir: Path, params: MaskParams | None = None) -> None:
    """Manual-label masks of the labelled segments only (a store of the same format as the automatic one),
    made with ``params`` (default :class:`MaskParams`: box-projected targets).

    Every cube of each scene with a labelled segment gets a mask, so the store lines up with the
    scene's cubes as the automatic one does; the masks are made from the scene seen through
    :meth:`SemiSupervisedSplit.labelled_view` (its labels hold the labelled segments' rows only), and
    every cube outside the labelled segments is then all UNCERTAIN, which the loss ignores: no manual
    label outside the labelled segments shapes a mask, and none reaches training.
    """
    split.check_manual_label_use(split.labelled)
    _write_manual_label_masks(run, list(split.labelled), step_dir, "manual-label masks", params, split)


def write_validation_masks(run: RunContext, step_dir: Path, params: MaskParams | None = None) -> None:
    """Manual-label masks of the validation scenes (a store as :func:`write_label_masks`'s, with ``params``;
    empty without any).

    They choose each training phase's checkpoint (the epoch of least validation loss) and feed no
    gradient. The test split's labels are never read here.

    Raises
    ------
    ZendarError
        When a scene is in both the validation and the test split.
    """
    scene_ids = run.dataset.scene_ids("val")
    shared = sorted(set(scene_ids) & set(run.dataset.scene_ids("test")))
    if shared:
        raise ZendarError(f"{run.root}: scenes {shared} are in both the val and the test split; the test split "
                          "may not choose checkpoints")
    _write_manual_label_masks(run, scene_ids, step_dir, "validation masks", params)


def _write_manual_label_masks(run: RunContext, scene_ids: list[str], step_dir: Path, description: str,
                              params: MaskParams | None, split: SemiSupervisedSplit | None = None) -> None:
    """Manual-label masks of ``scene_ids`` into a store in ``step_dir``; with ``split``, of its labelled
    segments only (:func:`write_label_masks`)."""
    parameters = {**mask_parameters(params), "kind": "labels"}
    store = MaskStore.create(step_dir / STORE_DIR, run.dataset, parameters, code_version=run.code_version)
    for scene_id in tqdm(scene_ids, desc=description, unit="scene"):
        if store.has_scene(scene_id, parameters, run.code_version):
            continue
        with run.dataset.open_scene(scene_id) as reader:
            view = reader if split is None else split.labelled_view(reader)
            masks = {}
            for radar in reader.sensors("radar"):
                timestamps, targets = scene_masks(view, radar, "labels", params=params, progress=False)
                if split is not None:
                    targets[~split.is_labelled(scene_id, timestamps)] = UNCERTAIN
                masks[radar] = (timestamps, targets)
            store.write_scene(scene_id, masks)


# --- inputs --------------------------------------------------------------------------------------


def scene_maps(reader: SceneReader, radar: str, cache_dir: Path, channels: InputChannels = InputChannels()) -> np.ndarray:
    """CNN input maps ``[N, C, R, D]`` float32 of one radar, memory-mapped from ``cache_dir``.

    The normalised log-power maps (``C = A``), followed by the optional ``channels``
    (:func:`zendar_baselines.cnn.input_channels.input_maps`). Written once per scene, radar and
    channel set (atomically: temporary name, then rename) and reused. The maps are streamed into a
    memory-mapped temporary, so they are renamed here rather than passed whole to
    :mod:`zendar_dataset.atomic_files`.
    """
    from zendar_baselines.cnn.input_channels import scene_input_maps

    suffix = "" if channels.is_paper_input else f"__{channels.name}"
    path = cache_dir / f"{reader.scene_id}__{radar}{suffix}.npy"
    if not path.is_file():
        n, n_range, n_doppler, n_rx = reader.array(f"radar/{radar}/cube").shape
        cache_dir.mkdir(parents=True, exist_ok=True)
        temp = temporary_sibling(path)
        try:
            shape = (n, channels.channels_per_map(n_rx), n_range, n_doppler)
            maps = np.lib.format.open_memmap(temp, mode="w+", dtype=np.float32, shape=shape)
            scene_input_maps(reader, radar, channels, out=maps)
            maps.flush()
            del maps
            os.replace(temp, path)
        finally:
            remove_temporary(temp)
    return np.load(path, mmap_mode="r")


# --- training ------------------------------------------------------------------------------------


def _frames(run: RunContext, scenes: list[str], store_dir: Path, split: SemiSupervisedSplit | None = None,
            channels: InputChannels = InputChannels()):
    """Training samples (windows of ``channels``' maps and the mask of their newest cube) of ``scenes``
    from a mask store, of each radar it holds masks of (the automatic labels leave out a radar whose
    maps the CFAR window does not fit).

    With ``split``, only the samples whose newest cube lies in a labelled segment (the manual-label
    phases); without, every sample (pretraining on automatic labels). The windows' older maps may
    come from outside the segments: they are radar data, not labels.
    """
    from torch.utils.data import ConcatDataset

    from zendar_baselines.cnn.mask_frames import MaskFrames, MaskFrameSubset

    store = MaskStore.open(store_dir, run.dataset)
    parts = []
    for scene_id in scenes:
        masks = store.scene(scene_id)
        with run.kept_scenes().opened(scene_id) as scene:
            reader = scene.reader
            for radar, (timestamps, targets) in masks.items():
                if not np.array_equal(timestamps, reader.timestamps(f"radar/{radar}")):
                    raise ZendarError(f"{store_dir}: the masks of {scene_id} {radar} do not match the dataset's cube "
                                      "times; the store was made from another dataset")
                maps = scene_maps(reader, radar, run.inputs_dir, channels)
                if split is None:
                    parts.append(MaskFrames(maps, targets, window=run.config.window))
                    continue
                # Sample i is the window ending at cube i (the first windows padded): its target is cube i's mask.
                chosen = np.flatnonzero(split.is_labelled(scene_id, timestamps))
                split.check_manual_label_times(scene_id, timestamps[chosen])
                if chosen.size:
                    parts.append(MaskFrameSubset(maps, targets, run.config.window, chosen))
    if split is not None and not parts:
        raise ZendarError(f"{store_dir}: no training sample of {scenes} has its newest cube in a labelled segment")
    return ConcatDataset(parts)


def train_row(run: RunContext, labels: TrainingLabels, row: RowSeed, out_dir: Path) -> Path:
    """Train one seed of one Table 1 row; returns the checkpoint chosen (recorded in ``checkpoint.json``).

    Supervised-only: the labelled part's manual masks with ``config.supervised``. Pretrained:
    every training scene's automatic masks with ``config.pretrain``, then the labelled part's
    manual masks with ``config.finetune`` starting from the pretraining epoch chosen. Every phase
    keeps the epoch of least loss on the validation masks (:func:`validation_frames`).
    ``checkpoint.json`` records every phase's losses per epoch, the epoch chosen and the validation
    data; ``curves.json`` the train and validation loss per epoch and phase.
    """
    from zendar_baselines.cnn.models import build_model, parameter_count
    from zendar_baselines.cnn.training import seed_everything, train

    config, split = run.config, labels.split
    split.check_manual_label_use(split.labelled)
    labelled = _frames(run, list(split.labelled), labels.masks_dir / STORE_DIR, split, row.inputs)
    in_channels = labelled.datasets[0].in_channels
    labelled, validation, validation_record = validation_frames(run, labels, labelled, row.inputs)

    def fresh_model():
        seed_everything(row.seed)
        return build_model(row.model_name, in_channels, config.width_scale, row.inputs.to_json()).to(run.device)

    results = {}
    init_from = None
    if row.pretrained:
        everything = _frames(run, sorted((*split.labelled, *split.unlabelled)), labels.auto_dir / STORE_DIR, channels=row.inputs)
        model = fresh_model()
        results["pretrain"] = train(
            model, everything, config.pretrain, seed=row.seed, out_dir=out_dir / "pretrain", device=run.device,
            validation=validation, progress=run.progress,
            description=f"{row.model_name} pretrain seed {row.seed} ({parameter_count(model):,} parameters)")
        init_from = results["pretrain"].checkpoint_path
    model = fresh_model()
    schedule = config.finetune if row.pretrained else config.supervised
    phase = "fine-tune" if row.pretrained else "supervised"
    results[phase] = train(
        model, labelled, schedule, seed=row.seed, out_dir=out_dir / phase, device=run.device, init_from=init_from,
        validation=validation, progress=run.progress,
        description=f"{row.model_name} {phase} seed {row.seed} ({parameter_count(model):,} parameters)")
    if ranks.is_main():  # under torchrun, the other ranks trained with this one and write nothing
        write_training_records(out_dir, row, results, validation_record)
    return results[phase].checkpoint_path


def validation_frames(run: RunContext, labels: TrainingLabels, labelled: ConcatDataset,
                      channels: InputChannels = InputChannels()) -> tuple[ConcatDataset, ConcatDataset, dict[str, Any]]:
    """The samples that choose the checkpoints (windows of ``channels``' maps), and the labelled
    samples left to train on.

    The validation scenes' manual-label masks (``labels.validation_dir``) when the dataset has
    validation scenes. Otherwise the last :data:`HOLD_OUT_FRACTION` of every labelled scene's and
    radar's samples, ``K - 1`` samples apart from the rest (so no map is in both), are held out of
    the manual-label training data, with a warning on stderr. Either way every K-th window is kept
    (windows that share no map).

    Returns
    -------
    labelled : ConcatDataset
        The labelled samples to train on.
    validation : ConcatDataset
    record : dict
        ``source`` (``"val split"`` or ``"held-out labelled training frames"``), ``scenes``,
        ``window_stride`` (K), ``n_samples``, and ``fraction`` for held-out frames.
    """
    from zendar_baselines.cnn.training import hold_out_tail

    window = run.config.window
    scene_ids = run.dataset.scene_ids("val")
    if scene_ids:
        validation = _every_kth(_frames(run, scene_ids, labels.validation_dir / STORE_DIR, channels=channels), window)
        return labelled, validation, {"source": "val split", "scenes": scene_ids, "window_stride": window,
                                      "n_samples": len(validation)}
    labelled, held_out = hold_out_tail(labelled, HOLD_OUT_FRACTION, gap=window - 1)
    validation = _every_kth(held_out, window)
    print(f"warning: {run.root} has no validation scenes; the last {HOLD_OUT_FRACTION:.0%} of every labelled "
          "training scene's frames are held out of training to choose the checkpoints", file=sys.stderr, flush=True)
    return labelled, validation, {"source": "held-out labelled training frames", "scenes": list(labels.split.labelled),
                                  "fraction": HOLD_OUT_FRACTION, "window_stride": window, "n_samples": len(validation)}


def _every_kth(data: ConcatDataset, k: int) -> ConcatDataset:
    # Windows k apart share no map: the validation loss costs 1/k of every window's and loses
    # little, as neighbouring windows hold K - 1 of the same maps.
    from torch.utils.data import ConcatDataset, Subset

    return ConcatDataset([Subset(part, range(0, len(part), k)) for part in data.datasets])


def _finite(values) -> list[float | None]:
    # A diverged epoch's NaN or infinite loss is recorded as null (strict JSON).
    return [float(v) if math.isfinite(v) else None for v in values]


def write_training_records(out_dir: Path, row: RowSeed, results: dict[str, TrainResult], validation: dict[str, Any]) -> None:
    """``checkpoint.json`` and ``curves.json`` of one row's seed from its phases' ``TrainResult`` s (in order).

    ``checkpoint.json``: ``checkpoint`` (the last phase's chosen checkpoint, relative to ``out_dir``),
    ``epoch_losses`` (the last phase's training losses), ``validation`` and per phase ``checkpoint``,
    ``last_checkpoint``, ``best_epoch``, ``epochs_run``, ``stopped_early``, ``train_losses`` and
    ``validation_losses``. ``curves.json``: per phase, one ``{"epoch", "train", "validation"}`` entry
    per epoch run and the ``best_epoch``.
    """
    phases = {
        name: {
            "checkpoint": str(result.checkpoint_path.relative_to(out_dir)),
            "last_checkpoint": str(result.last_checkpoint_path.relative_to(out_dir)),
            "best_epoch": result.best_epoch,
            "epochs_run": len(result.epoch_losses),
            "stopped_early": result.stopped_early,
            "train_losses": _finite(result.epoch_losses),
            "validation_losses": _finite(result.validation_losses),
        }
        for name, result in results.items()
    }
    final = list(phases.values())[-1]
    write_json_atomic(out_dir / CHECKPOINT_RECORD, {"checkpoint": final["checkpoint"], "epoch_losses": final["train_losses"],
                                                    "validation": validation, "phases": phases})
    curves = [
        {"phase": name, "best_epoch": phase["best_epoch"],
         "epochs": [{"epoch": epoch, "train": train_loss,
                     "validation": phase["validation_losses"][epoch - 1] if epoch <= len(phase["validation_losses"]) else None}
                    for epoch, train_loss in enumerate(phase["train_losses"], 1)]}
        for name, phase in phases.items()
    ]
    write_json_atomic(out_dir / CURVES_FILE, {"format": "zendar-bench-curves", "format_version": 1, "row": row.row_key,
                                              "seed": row.seed, "validation": validation["source"], "phases": curves})


def final_checkpoint(seed_dir: Path) -> Path:
    """The checkpoint a row's seed directory recorded."""
    return seed_dir / read_json(seed_dir / CHECKPOINT_RECORD)["checkpoint"]
