"""Training and inference of the CNN dynamic-object detectors (paper §4.2), single- or multi-process.

``train`` fits a model that maps stacked range-Doppler maps ``[B, C, R, D]`` to per-cell logits
``[B, 1, R, D]`` with Adam and a binary cross-entropy on the cells whose mask is 0 (background) or 1
(moving); uncertain cells (2) give no gradient. After every epoch it measures the same loss on
validation data (when given; weighted by the validation masks' own class balance), keeps the
checkpoint of the epoch with the lowest validation loss and that of the last epoch (older ones are
removed), and may stop early. Called again with the same inputs, it resumes from the latest
checkpoint of the run, reproducing an uninterrupted run exactly.

Reproducibility: the sample order of epoch ``e`` is a permutation drawn from ``(seed, e)`` alone
(``DistributedSampler``), and the torch / numpy / python generators are re-seeded at the start of
every epoch from ``(seed, e, rank)``; nothing depends on how many epochs ran in this process. While
training, torch runs its deterministic algorithms where it has them and a fixed number of intra-op
threads (:data:`TRAINING_THREADS`), so the reductions' summation order does not follow the machine's
core count.

Multi-process: under ``torchrun`` (``WORLD_SIZE`` > 1) each process takes ``batch_size / WORLD_SIZE``
samples of every global batch, and the loss is normalised by the global count of labelled cells, so
the gradient equals that of one process on the whole global batch (up to float summation order).
Batch-norm statistics are per process, as usual with ``DistributedDataParallel``: a model with batch
norm trains slightly differently on several processes.
"""

from __future__ import annotations

import hashlib
import math
import os
import random
import re
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.distributed as dist
import torch.utils.deterministic
import torch.nn.functional as F
from torch import nn
from torch.utils.data import ConcatDataset, DataLoader, Dataset, Subset
from torch.utils.data.distributed import DistributedSampler
from tqdm.auto import tqdm

from zendar_dataset.errors import ZendarError

from zendar_baselines.cnn.checkpoints import (
    CheckpointIntegrityError,
    load_checkpoint,
    load_model_state,
    model_architecture,
    remove_checkpoint,
    save_checkpoint,
    unwrap_model,
)
from zendar_baselines.code_version import code_version
from zendar_baselines.cnn.schedule import Schedule
from zendar_baselines.cnn.mask_frames import MaskFrames
from zendar_baselines.labels.mask_classes import BACKGROUND, MOVING, UNCERTAIN

MAX_POS_WEIGHT = 100.0
#: Intra-op threads while training, whatever the machine's core count: a convolution's weight
#: gradient sums over the batch in per-thread partial sums, whose number (and so the rounding)
#: follows the thread count (1 and 2 threads give other weights after 3 steps). One: at the demo
#: config's widths two one-thread trainings side by side (``zendar-bench``'s worker processes) finish
#: sooner than the two one after the other on 2 threads (benchmarks/bench_seed_workers.py).
TRAINING_THREADS = 1
#: The widest vector instructions oneDNN's convolutions may use. oneDNN picks its kernels, and with
#: them the summation order, by the CPU's vector width: unpinned, an AVX-512 and an AVX2 CPU train to
#: other weights. AVX2 runs on both. oneDNN reads it once, at the process's first convolution, so it
#: is set (unless the environment sets it) when this module is imported, before any model runs.
ONEDNN_MAX_CPU_ISA = "AVX2"
os.environ.setdefault("ONEDNN_MAX_CPU_ISA", ONEDNN_MAX_CPU_ISA)
#: Whether torch's deterministic mode fills every newly allocated tensor with NaN
#: (``torch.utils.deterministic.fill_uninitialized_memory``, on by default in that mode). The filling
#: exists to expose reads of uninitialised memory, which no op of these models makes: the weights and
#: predictions of every architecture are bit-identical with and without it (tests/baselines/
#: test_training.py), and it made a demo training epoch 8-13 % longer (width 0.125, batch 16, one
#: thread; ``benchmarks/bench_training.py``, docs/baselines.md "Speed").
FILL_UNINITIALIZED_MEMORY = False
#: The layout of the models' weights and inputs while training and predicting. In channels-last
#: oneDNN's convolutions and ATen's batch norm need no reorders: a training step of the demo config's
#: DenseNet-37 and FPN-ResNet-34 (width 0.125, batch 16 of 12 × 256 × 64, one thread) took 0.322 and
#: 0.253 s against 0.413 and 0.323 s in NCHW (docs/baselines.md, "Speed"). The weights after three
#: steps are as independent of ATen's AVX2 / AVX-512 kernels as in NCHW (the same SHA-256 with
#: ``ATEN_CPU_CAPABILITY=avx2``; benchmarks/bench_reproducibility.py).
MEMORY_FORMAT = torch.channels_last
_CHECKPOINT_NAME = re.compile(r"^epoch-(\d{4,})\.pt$")


@dataclass(frozen=True)
class TrainResult:
    """What ``train`` made.

    Attributes
    ----------
    checkpoint_path : Path
        The checkpoint of the epoch chosen: the lowest validation loss, or the last epoch without
        validation data (``out_dir/epoch-NNNN.pt``).
    last_checkpoint_path : Path
        The checkpoint of the last epoch run.
    best_epoch : int
        The epoch chosen (1-based).
    epoch_losses : tuple of float
        Mean training loss per labelled cell of every epoch run (resumed epochs included).
    validation_losses : tuple of float
        Mean validation loss per labelled cell after every epoch run; empty without validation data.
    stopped_early : bool
        Training ended before ``schedule.epochs`` because the validation loss stopped falling.
    resumed_from_epoch : int
        Epochs read back from an earlier call (0: trained from the start).
    pos_weight : float
        Weight of the moving class in the loss.
    """

    checkpoint_path: Path
    last_checkpoint_path: Path
    best_epoch: int
    epoch_losses: tuple[float, ...]
    validation_losses: tuple[float, ...]
    stopped_early: bool
    resumed_from_epoch: int
    pos_weight: float


def masked_bce(logits: torch.Tensor, targets: torch.Tensor, pos_weight: float) -> tuple[torch.Tensor, torch.Tensor]:
    """Summed binary cross-entropy over labelled cells, and their count.

    Parameters
    ----------
    logits : Tensor, float, shape [B, 1, R, D]
        The model's output.
    targets : Tensor, uint8, shape [B, R, D]
        0 background, 1 moving, 2 uncertain (left out: no loss, no gradient).
    pos_weight : float
        Multiplies the loss of moving cells.

    Returns
    -------
    loss_sum : Tensor, scalar
        ``sum over labelled cells of -(w y log σ(z) + (1 - y) log(1 - σ(z)))``.
    n_labelled : Tensor, scalar float
        Cells with target 0 or 1.
    """
    if logits.ndim != 4 or logits.shape[1] != 1 or logits.shape[0] != targets.shape[0] or logits.shape[2:] != targets.shape[1:]:
        raise ZendarError(
            f"masked_bce: logits {tuple(logits.shape)} do not fit targets {tuple(targets.shape)} "
            "(expected logits [B, 1, R, D] for targets [B, R, D])"
        )
    labelled = targets != UNCERTAIN
    # Ignored cells are replaced before the loss, not multiplied by 0 after it: a non-finite logit
    # there (NaN · 0 = NaN) must reach neither the sum nor the gradient.
    logits = torch.where(labelled, logits[:, 0], torch.zeros((), dtype=logits.dtype, device=logits.device))
    target_float = (targets == MOVING).to(logits.dtype)
    per_cell = F.binary_cross_entropy_with_logits(
        logits, target_float, pos_weight=torch.tensor(pos_weight, dtype=logits.dtype, device=logits.device), reduction="none"
    )
    loss_sum = torch.where(labelled, per_cell, torch.zeros((), dtype=per_cell.dtype, device=per_cell.device)).sum()
    return loss_sum, labelled.sum().to(logits.dtype)


def _mask_class_counts(data: Dataset) -> tuple[int, int]:
    if isinstance(data, MaskFrames):
        return data.class_counts()
    if isinstance(data, ConcatDataset):
        counts = [_mask_class_counts(part) for part in data.datasets]
        return sum(c[0] for c in counts), sum(c[1] for c in counts)
    background = moving = 0
    for index in range(len(data)):
        target = torch.as_tensor(data[index][1])
        background += int((target == BACKGROUND).sum())
        moving += int((target == MOVING).sum())
    return background, moving


def positive_class_weight(data: Dataset) -> float:
    """Loss weight of moving cells: ``sqrt(background cells / moving cells)``, clipped to [1, 100].

    Moving cells are about 1 % of labelled cells. The full ratio (~99) would balance the classes but
    move the 0.5 decision threshold so far that most noise peaks near a car are called moving; no
    weight lets the network settle on "all background" early. The square root (~10) is the usual
    compromise: rare positives still drive the gradient while probabilities stay usable at 0.5.
    The table's metric is an area under a curve, which no monotone re-weighting changes much.
    Counted over the training masks once (uncertain cells left out); 1.0 when there is no moving cell.
    """
    background, moving = _mask_class_counts(data)
    if moving == 0:
        return 1.0
    return float(min(max(math.sqrt(background / moving), 1.0), MAX_POS_WEIGHT))


def hold_out_tail(data: ConcatDataset, fraction: float, gap: int) -> tuple[ConcatDataset, ConcatDataset]:
    """Split every part of ``data`` (one scene and radar each) in time: its last samples are held out.

    Parameters
    ----------
    data : ConcatDataset
        Parts of consecutive samples, e.g. one ``MaskFrames`` per scene and radar.
    fraction : float
        In (0, 1): the share of each part's samples held out, rounded up (at least one).
    gap : int
        Samples dropped between the kept and the held-out ones of a part: ``K - 1`` for windows of
        K maps, so that no map is in both (neighbouring frames are near copies of each other).

    Returns
    -------
    kept, held_out : ConcatDataset
        ``Subset`` s of the parts, in order; deterministic (no random draw).

    Raises
    ------
    ZendarError
        When a part is too short to keep a sample after holding out its tail and the gap.
    """
    if not 0.0 < fraction < 1.0:
        raise ZendarError(f"hold_out_tail: fraction must be in (0, 1), found {fraction!r}")
    kept, held_out = [], []
    for index, part in enumerate(data.datasets):
        n = len(part)
        n_held = max(1, math.ceil(fraction * n))
        n_kept = n - n_held - gap
        if n_kept < 1:
            raise ZendarError(
                f"hold_out_tail: part {index} has {n} samples, too few to hold out {n_held} of them "
                f"after a gap of {gap} and keep one for training"
            )
        kept.append(Subset(part, range(n_kept)))
        held_out.append(Subset(part, range(n - n_held, n)))
    return ConcatDataset(kept), ConcatDataset(held_out)


def seed_everything(seed: int) -> None:
    """Seed python's ``random``, numpy's global generator and torch (CPU and every CUDA device)."""
    random.seed(seed)
    np.random.seed(seed % 2**32)
    torch.manual_seed(seed)


@contextmanager
def deterministic_torch(threads: int | None = None) -> Iterator[None]:
    """Within the block: torch's deterministic algorithms (a warning where an op has none) and ``threads``
    intra-op threads (default :data:`TRAINING_THREADS`), deterministic mode's filling of new tensors
    as :data:`FILL_UNINITIALIZED_MEMORY` says; the previous settings come back afterwards.

    On CUDA, cuBLAS needs ``CUBLAS_WORKSPACE_CONFIG`` for deterministic matrix products; it is set
    (``:4096:8``) unless the environment already sets it.
    """
    previous = (torch.are_deterministic_algorithms_enabled(), torch.is_deterministic_algorithms_warn_only_enabled(),
                torch.get_num_threads(), torch.utils.deterministic.fill_uninitialized_memory)
    os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")
    try:
        torch.use_deterministic_algorithms(True, warn_only=True)
        torch.utils.deterministic.fill_uninitialized_memory = FILL_UNINITIALIZED_MEMORY
        torch.set_num_threads(TRAINING_THREADS if threads is None else threads)
        yield
    finally:
        torch.use_deterministic_algorithms(previous[0], warn_only=previous[1])
        torch.utils.deterministic.fill_uninitialized_memory = previous[3]
        torch.set_num_threads(previous[2])


def _epoch_seed(seed: int, epoch: int, rank: int) -> int:
    return int(np.random.SeedSequence([seed, epoch, rank]).generate_state(1, dtype=np.uint64)[0] >> 1)


def state_sha256(model: nn.Module) -> str:
    """SHA-256 over a model's state (names, dtypes, shapes and bytes of every tensor, in name order)."""
    digest = hashlib.sha256()
    for name, tensor in sorted(unwrap_model(model).state_dict().items()):
        flat = tensor.detach().cpu().contiguous().reshape(-1)
        digest.update(f"{name}\0{flat.dtype}\0{tuple(tensor.shape)}\0".encode())
        digest.update(flat.view(torch.uint8).numpy().tobytes())
    return digest.hexdigest()


@dataclass(frozen=True)
class _Process:
    rank: int
    world_size: int
    device: torch.device
    started_group: bool

    @property
    def is_main(self) -> bool:
        return self.rank == 0


@contextmanager
def _process_group(device: str | torch.device) -> Iterator[_Process]:
    world_size = int(os.environ.get("WORLD_SIZE", "1"))
    device = torch.device(device)
    if world_size <= 1:
        yield _Process(rank=0, world_size=1, device=device, started_group=False)
        return
    started = False
    if not dist.is_initialized():
        backend = "nccl" if device.type == "cuda" else "gloo"
        dist.init_process_group(backend=backend)
        started = True
    if device.type == "cuda" and device.index is None:
        device = torch.device("cuda", int(os.environ.get("LOCAL_RANK", "0")))
    if device.type == "cuda":
        torch.cuda.set_device(device)
    try:
        yield _Process(rank=dist.get_rank(), world_size=dist.get_world_size(), device=device, started_group=started)
    finally:
        if started:
            dist.destroy_process_group()


def _broadcast(value: Any, process: _Process) -> Any:
    if process.world_size == 1:
        return value
    box = [value]
    dist.broadcast_object_list(box, src=0)
    return box[0]


def checkpoint_path(out_dir: str | os.PathLike, epoch: int) -> Path:
    """``out_dir/epoch-NNNN.pt``: the checkpoint written after ``epoch`` epochs."""
    return Path(out_dir) / f"epoch-{epoch:04d}.pt"


def _run_identity(model: nn.Module, schedule: Schedule, seed: int, n_samples: int, n_validation_samples: int,
                  initial_sha256: str) -> dict[str, Any]:
    # Everything that decides the weights after epoch e and the epoch chosen, except the number of
    # epochs still to run.
    return {
        "architecture": model_architecture(model),
        "lr": float(schedule.lr),
        "batch_size": int(schedule.batch_size),
        "patience": schedule.patience,
        "seed": int(seed),
        "n_samples": int(n_samples),
        "n_validation_samples": int(n_validation_samples),
        "initial_weights_sha256": initial_sha256,
        "code_version": code_version(),
    }


def _find_resume_point(out_dir: Path, identity: dict[str, Any], epochs: int) -> tuple[int, dict[str, Any] | None]:
    """The latest usable checkpoint of this run with at most ``epochs`` epochs: (epoch, checkpoint)."""
    for epoch in sorted(_checkpoint_epochs(out_dir), reverse=True):
        path = checkpoint_path(out_dir, epoch)
        try:
            checkpoint = load_checkpoint(path)
        except CheckpointIntegrityError as exc:
            # A write cut short (the manifest did not record it) is recomputed from the epoch before.
            tqdm.write(f"not resuming from {path}: {exc}")
            continue
        recorded = checkpoint.get("run")
        if recorded != identity:
            differing = sorted(key for key in identity if not isinstance(recorded, dict) or recorded.get(key) != identity[key])
            raise ZendarError(
                f"{out_dir}: holds checkpoints of another run (differs in {', '.join(differing)}); "
                "choose another out_dir or remove its epoch-*.pt files"
            )
        if epoch <= epochs:
            return epoch, checkpoint
    return 0, None


def _checkpoint_epochs(out_dir: Path) -> list[int]:
    """Epochs of the ``epoch-NNNN.pt`` files in ``out_dir``."""
    if not out_dir.is_dir():
        return []
    return [int(match[1]) for entry in out_dir.iterdir() if (match := _CHECKPOINT_NAME.match(entry.name))]


def _remove_checkpoints_but(out_dir: Path, keep: set[int]) -> None:
    for epoch in _checkpoint_epochs(out_dir):
        if epoch not in keep:
            remove_checkpoint(checkpoint_path(out_dir, epoch))


def _check_schedule(schedule: Schedule, world_size: int, validating: bool) -> None:
    if not (isinstance(schedule.epochs, int) and schedule.epochs >= 1):
        raise ZendarError(f"schedule.epochs must be a positive integer, found {schedule.epochs!r}")
    if not (isinstance(schedule.batch_size, int) and schedule.batch_size >= 1):
        raise ZendarError(f"schedule.batch_size must be a positive integer, found {schedule.batch_size!r}")
    if not (math.isfinite(schedule.lr) and schedule.lr >= 0):
        raise ZendarError(f"schedule.lr must be a finite number >= 0, found {schedule.lr!r}")
    if schedule.patience is not None and not (isinstance(schedule.patience, int) and schedule.patience >= 1):
        raise ZendarError(f"schedule.patience must be None or a positive integer, found {schedule.patience!r}")
    if schedule.patience is not None and not validating:
        raise ZendarError(f"schedule.patience {schedule.patience} stops on the validation loss: give validation data")
    if schedule.batch_size % world_size:
        raise ZendarError(
            f"schedule.batch_size {schedule.batch_size} (the global batch) is not divisible by the "
            f"{world_size} processes (WORLD_SIZE)"
        )


def train(
    model: nn.Module,
    data: Dataset,
    schedule: Schedule,
    *,
    seed: int,
    out_dir: str | os.PathLike,
    device: str | torch.device = "cpu",
    init_from: str | os.PathLike | None = None,
    validation: Dataset | None = None,
    progress: bool = True,
    description: str = "",
    num_workers: int = 0,
) -> TrainResult:
    """Train ``model`` in place on ``data``: Adam, masked BCE, the epoch of least validation loss kept, resumable.

    Parameters
    ----------
    model : nn.Module
        Freshly built (its initial weights are part of the run's identity, so build it after
        ``seed_everything(seed)`` for a reproducible run); maps float32 ``[B, C, R, D]`` to logits
        ``[B, 1, R, D]`` and carries ``model.architecture``. Holds the weights of the last epoch run
        on return (those of the chosen epoch are in ``checkpoint_path``), in :data:`MEMORY_FORMAT`.
    data : Dataset
        Samples ``(input float32 [C, R, D], mask uint8 [R, D])``, e.g. ``MaskFrames`` or a
        ``ConcatDataset`` of them.
    schedule : Schedule
        Learning rate, global batch size (split evenly over processes), epochs at most and the
        early-stopping patience.
    seed : int
        Decides the sample order and every random draw during training.
    out_dir : path
        Checkpoints ``epoch-NNNN.pt`` and ``manifest.json``; one run per directory. Only the
        checkpoints of the best epoch so far and of the last epoch stay. When it already holds
        checkpoints of this run (same architecture, initial weights, lr, batch size, patience, seed,
        sample counts and code version), training resumes after the latest one with at most
        ``schedule.epochs`` epochs (and returns at once when the run had finished).
    device : str or torch.device
        ``"cpu"`` or ``"cuda"`` (under torchrun each process takes ``cuda:LOCAL_RANK``).
    init_from : path, optional
        A checkpoint whose weights (same architecture) replace the model's before training
        (pretraining → fine-tuning); the optimizer starts fresh.
    validation : Dataset, optional
        Samples as ``data``'s; after every epoch the model (in eval mode) is scored on them with the
        training loss, its positive weight counted on the validation masks (so that the losses of
        phases and rows scored on the same masks compare), and the epoch of the lowest score is
        chosen (the earliest of equal ones). None: the last epoch is chosen and
        ``schedule.patience`` must be None.
    progress : bool
        Show a tqdm bar with the epoch and running loss (rank 0 only).
    description : str
        Prefix of the progress bar.
    num_workers : int
        DataLoader worker processes.

    Returns
    -------
    TrainResult

    Raises
    ------
    ZendarError
        For an invalid schedule, empty data, validation data without a labelled cell, a model output
        of the wrong shape, ``out_dir`` holding another run, or an unusable ``init_from`` checkpoint
        (CheckpointError).
    """
    out_dir = Path(out_dir)
    with _process_group(device) as process, deterministic_torch():
        _check_schedule(schedule, process.world_size, validation is not None)
        if len(data) == 0:
            raise ZendarError("train: the dataset has no samples")
        if validation is not None and len(validation) == 0:
            raise ZendarError("train: the validation dataset has no samples")
        if process.device.type == "cuda":
            torch.backends.cudnn.benchmark = False
            torch.backends.cudnn.deterministic = True
        model.to(process.device, memory_format=MEMORY_FORMAT)
        init_record: dict[str, Any] = {}
        if init_from is not None:
            init_checkpoint = load_checkpoint(init_from, expected_architecture=model_architecture(model), model=model)
            init_record = {"path": str(Path(init_from).resolve()), "epoch": int(init_checkpoint["epoch"])}
        trained: nn.Module = model
        if process.world_size > 1:
            # The wrapper broadcasts rank 0's weights, so every rank starts from the same ones.
            device_ids = [process.device.index] if process.device.type == "cuda" else None
            trained = nn.parallel.DistributedDataParallel(model, device_ids=device_ids)
        n_validation = 0 if validation is None else len(validation)
        identity = _run_identity(model, schedule, seed, len(data), n_validation, state_sha256(model))
        start_epoch, resumed, failure = 0, None, None
        if process.is_main:
            try:
                out_dir.mkdir(parents=True, exist_ok=True)
                start_epoch, resumed = _find_resume_point(out_dir, identity, schedule.epochs)
            except (ZendarError, OSError) as exc:
                failure = exc
        # Rank 0 alone decides, and its error reaches every rank (none is left waiting for the others).
        start_epoch, failure = _broadcast((start_epoch, failure), process)
        if failure is not None:
            raise failure

        optimizer = torch.optim.Adam(trained.parameters(), lr=schedule.lr)
        history = _History()
        if start_epoch > 0:
            resume_path = checkpoint_path(out_dir, start_epoch)
            checkpoint = resumed if process.is_main else load_checkpoint(resume_path, identity["architecture"])
            load_model_state(model, checkpoint, resume_path)
            optimizer.load_state_dict(checkpoint["optimizer_state"])
            history = _History.from_checkpoint(checkpoint, start_epoch)
            pos_weight = float(checkpoint["pos_weight"])
        else:
            pos_weight = positive_class_weight(data)
        # The validation masks' own weight: validation losses then compare across phases and rows.
        validation_pos_weight = None if validation is None else positive_class_weight(validation)

        sampler = DistributedSampler(
            data, num_replicas=process.world_size, rank=process.rank, shuffle=True, seed=seed, drop_last=False
        )
        loader = DataLoader(
            data,
            batch_size=schedule.batch_size // process.world_size,
            sampler=sampler,
            num_workers=num_workers,
            generator=torch.Generator().manual_seed(seed),
            pin_memory=process.device.type == "cuda",
        )
        validation_loader = None
        if validation is not None:
            # Every process scores its own share (every world_size-th sample); the sums are all-reduced.
            validation_loader = DataLoader(
                Subset(validation, range(process.rank, len(validation), process.world_size)),
                batch_size=schedule.batch_size // process.world_size, shuffle=False, num_workers=num_workers,
                pin_memory=process.device.type == "cuda",
            )
        config = {"schedule": asdict(schedule), "seed": int(seed), "world_size": process.world_size,
                  "init_from": init_record, "description": description}
        remaining = 0 if history.finished(schedule) else schedule.epochs - start_epoch
        bar = tqdm(
            total=remaining * len(loader),
            desc=description or "train",
            disable=not (progress and process.is_main) or remaining == 0,
            leave=False,
            unit="batch",
        )
        with bar:
            for epoch in range(start_epoch + 1, schedule.epochs + 1):
                if history.finished(schedule):
                    break
                sampler.set_epoch(epoch)
                epoch_seed = _epoch_seed(seed, epoch, process.rank)
                seed_everything(epoch_seed)
                loader.generator.manual_seed(epoch_seed)  # worker seeds, independent of epochs run before
                train_loss = _train_epoch(trained, loader, optimizer, pos_weight, process, bar, epoch, schedule.epochs, description)
                validation_loss = None
                if validation_loader is not None:
                    validation_loss = _validation_loss(model, validation_loader, validation_pos_weight, process)
                    bar.set_postfix(loss=f"{train_loss:.4f}", val=f"{validation_loss:.4f}")
                history.add(train_loss, validation_loss)
                if process.is_main:
                    save_checkpoint(
                        checkpoint_path(out_dir, epoch), model, optimizer, epoch, config,
                        extra={
                            "run": identity,
                            **history.to_checkpoint(),
                            "pos_weight": pos_weight,
                            "validation_pos_weight": validation_pos_weight,
                            "rng_state": {"seed": int(seed), "derivation": "SeedSequence([seed, epoch, rank]) at each epoch's start"},
                        },
                    )
                    # Only once the new checkpoint is on disk and vouched for: the best and the last stay.
                    _remove_checkpoints_but(out_dir, {epoch, history.best_epoch})
        epochs_run = len(history.train_losses)
        if remaining == 0 and process.is_main and progress:
            tqdm.write(f"{description or 'train'}: {epochs_run} epochs already in {checkpoint_path(out_dir, epochs_run)}")
        if process.world_size > 1:
            dist.barrier()  # every rank returns only once rank 0's last checkpoint is on disk
        return TrainResult(
            checkpoint_path=checkpoint_path(out_dir, history.best_epoch),
            last_checkpoint_path=checkpoint_path(out_dir, epochs_run),
            best_epoch=history.best_epoch,
            epoch_losses=tuple(history.train_losses),
            validation_losses=tuple(history.validation_losses),
            stopped_early=epochs_run < schedule.epochs,
            resumed_from_epoch=start_epoch,
            pos_weight=pos_weight,
        )


@dataclass
class _History:
    """Losses of the epochs run so far and the epoch chosen among them (0 before the first)."""

    train_losses: list[float] = field(default_factory=list)
    validation_losses: list[float] = field(default_factory=list)
    best_epoch: int = 0

    @classmethod
    def from_checkpoint(cls, checkpoint: dict[str, Any], epoch: int) -> _History:
        return cls([float(v) for v in checkpoint["losses"][:epoch]],
                   [float(v) for v in checkpoint["validation_losses"][:epoch]], int(checkpoint["best_epoch"]))

    def add(self, train_loss: float, validation_loss: float | None) -> None:
        self.train_losses.append(train_loss)
        epoch = len(self.train_losses)
        if validation_loss is None:
            self.best_epoch = epoch
            return
        self.validation_losses.append(validation_loss)
        # Strictly lower: of equal losses the earlier epoch stays (NaN never improves on a number).
        if self.best_epoch == 0 or validation_loss < self.validation_losses[self.best_epoch - 1]:
            self.best_epoch = epoch

    def finished(self, schedule: Schedule) -> bool:
        """Every epoch ran, or ``schedule.patience`` epochs in a row did not improve on the best."""
        epochs_run = len(self.train_losses)
        if epochs_run >= schedule.epochs:
            return True
        return schedule.patience is not None and epochs_run > 0 and epochs_run - self.best_epoch >= schedule.patience

    def to_checkpoint(self) -> dict[str, Any]:
        return {"losses": list(self.train_losses), "validation_losses": list(self.validation_losses),
                "best_epoch": self.best_epoch}


def _validation_loss(model: nn.Module, loader: DataLoader, pos_weight: float, process: _Process) -> float:
    """The mean masked loss per labelled cell of ``model`` (eval mode) over every process's share."""
    if process.world_size > 1:
        # Batch-norm buffers drift apart per process; rank 0's are the ones its checkpoint stores.
        for buffer in model.buffers():
            dist.broadcast(buffer, src=0)
    was_training = model.training
    model.eval()
    totals = torch.zeros(2, dtype=torch.float64)
    try:
        with torch.inference_mode():
            for inputs, targets in loader:
                logits = model(inputs.to(process.device, memory_format=MEMORY_FORMAT, non_blocking=True))
                loss_sum, n_labelled = masked_bce(logits, targets.to(process.device, non_blocking=True), pos_weight)
                totals += torch.stack([loss_sum, n_labelled]).to(torch.float64).cpu()
    finally:
        model.train(was_training)
    if process.world_size > 1:
        dist.all_reduce(totals)
    if float(totals[1]) == 0.0:
        raise ZendarError("train: the validation masks have no labelled cell (every cell uncertain)")
    return float(totals[0] / totals[1])


def _train_epoch(
    trained: nn.Module,
    loader: DataLoader,
    optimizer: torch.optim.Optimizer,
    pos_weight: float,
    process: _Process,
    bar: tqdm,
    epoch: int,
    epochs: int,
    description: str,
) -> float:
    """One epoch; the mean loss per labelled cell over all processes."""
    trained.train()
    bar.set_description(f"{description + ' ' if description else ''}epoch {epoch}/{epochs}")
    epoch_sum = torch.zeros(2, dtype=torch.float64)
    for inputs, targets in loader:
        inputs = inputs.to(process.device, memory_format=MEMORY_FORMAT, non_blocking=True)
        targets = targets.to(process.device, non_blocking=True)
        logits = trained(inputs)
        loss_sum, n_labelled = masked_bce(logits, targets, pos_weight)
        totals = torch.stack([loss_sum.detach(), n_labelled]).to(torch.float64)
        if process.world_size > 1:
            dist.all_reduce(totals)
        # DistributedDataParallel averages gradients over processes; multiplying by their number
        # makes the step that of the global batch's mean over its labelled cells.
        loss = loss_sum * (process.world_size / max(float(totals[1]), 1.0))
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        epoch_sum += totals.cpu()
        bar.update(1)
        bar.set_postfix(loss=f"{float(epoch_sum[0] / max(float(epoch_sum[1]), 1.0)):.4f}")
    return float(epoch_sum[0] / max(float(epoch_sum[1]), 1.0))


def predict_masks(
    model: nn.Module,
    inputs: np.ndarray | torch.Tensor,
    batch_size: int,
    device: str | torch.device = "cpu",
) -> np.ndarray:
    """Per-cell probability of a moving object.

    Parameters
    ----------
    model : nn.Module
        Maps ``[B, C, R, D]`` to logits ``[B, 1, R, D]``; run in eval mode (restored afterwards),
        moved to ``device`` and :data:`MEMORY_FORMAT` (in place, as ``Module.to`` does).
    inputs : array, float32, shape [N, C, R, D]
        Stacked windows (``stack_window``); a memory-mapped array is read one batch at a time.
    batch_size : int
    device : str or torch.device

    Returns
    -------
    ndarray, float32, shape [N, R, D]
        ``sigmoid(logit)`` in [0, 1].

    Runs on :data:`TRAINING_THREADS` intra-op threads (:func:`deterministic_torch`), whatever the
    caller set: a convolution's sums, and so the last bits of a probability, follow the thread
    count, and a model scored in ``zendar-bench``'s one-thread workers must give the same
    predictions when ``zendar-bench verify`` or a user scores it again.
    """
    if getattr(inputs, "ndim", None) != 4:
        raise ZendarError(f"predict_masks: expected inputs [N, C, R, D], found shape {tuple(getattr(inputs, 'shape', ()))}")
    if not (isinstance(batch_size, int) and batch_size >= 1):
        raise ZendarError(f"predict_masks: batch_size must be a positive integer, found {batch_size!r}")
    n, _, n_range, n_doppler = inputs.shape
    probabilities = np.empty((n, n_range, n_doppler), dtype=np.float32)
    was_training = model.training
    model.to(device, memory_format=MEMORY_FORMAT).eval()
    try:
        with deterministic_torch(), torch.inference_mode():
            for start in range(0, n, batch_size):
                batch = torch.as_tensor(np.asarray(inputs[start : start + batch_size], dtype=np.float32))
                batch = batch.to(device, memory_format=MEMORY_FORMAT)
                logits = model(batch)
                if logits.shape != (len(batch), 1, n_range, n_doppler):
                    raise ZendarError(
                        f"predict_masks: model returned {tuple(logits.shape)} for input {tuple(batch.shape)}; "
                        f"expected [{len(batch)}, 1, {n_range}, {n_doppler}]"
                    )
                probabilities[start : start + len(batch)] = torch.sigmoid(logits[:, 0].float()).cpu().numpy()
    finally:
        model.train(was_training)
    return probabilities


__all__ = [
    "MAX_POS_WEIGHT",
    "MEMORY_FORMAT",
    "FILL_UNINITIALIZED_MEMORY",
    "ONEDNN_MAX_CPU_ISA",
    "TRAINING_THREADS",
    "TrainResult",
    "checkpoint_path",
    "deterministic_torch",
    "hold_out_tail",
    "masked_bce",
    "positive_class_weight",
    "predict_masks",
    "seed_everything",
    "state_sha256",
    "train",
]
