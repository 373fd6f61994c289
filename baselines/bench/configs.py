"""Benchmark configurations: ``paper`` (the paper's schedule, §4.1–4.2), ``gpu`` for one GPU, and
``demo`` / ``tiny`` for CPUs.

The paper trains with Adam: pretraining on automatic labels at lr 1e-4, batch 8, 100 epochs;
fine-tuning on manual labels at lr 1e-5, 80 epochs. It does not give a schedule for the
supervised-only rows; those train from scratch on the manual labels with the pretraining lr (a
fine-tuning lr of 1e-5 barely moves freshly initialised weights) for as many epochs as fine-tuning.
``demo`` and ``tiny`` keep every architecture's depth and the procedure, and shrink what a laptop
cannot afford: channel widths (``width_scale``), epochs and the simulated dataset.

Every phase keeps the epoch of least validation loss (the validation scenes' manual-label masks);
``demo`` and ``tiny`` also stop a phase after ``patience`` epochs without a lower validation loss, so
their epochs are a ceiling, and their learning curves (``curves.png``) flatten before it. ``gpu`` is the ``demo`` procedure at the
published widths (``width_scale`` 1.0) on four times the ``demo`` dataset with longer schedules,
sized to finish within an hour on one H100/H200 (``benchmarks/bench_paper_projection.py --config
gpu`` projects its training time from counted FLOPs). Budgets
compare in windows seen (one window = one gradient sample): with L labelled windows and about
L / ``labelled_fraction`` windows in every training scene, a pretrained row sees at most
``pretrain.epochs * L / labelled_fraction + finetune.epochs * L`` windows and a supervised-only row
``supervised.epochs * L``; ``supervised.epochs = pretrain.epochs / labelled_fraction + finetune.epochs``
makes the two ceilings equal (a test checks it), with the same batch, patience and learning rate as
pretraining. The supervised rows stop long before their ceiling: on one labelled scene their
validation loss is least after 7 demo epochs (15 tiny) and rises after (docs/baselines.md). The
schedules were set from validation curves, never from test scores.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

from zendar_dataset.errors import ZendarError

from zendar_baselines.cnn.models import MODEL_NAMES
from zendar_baselines.cnn.schedule import Schedule

__all__ = ["CONFIGS", "MODEL_NAMES", "BenchConfig", "Schedule", "get_config"]


@dataclass(frozen=True)
class BenchConfig:
    """Everything ``zendar-bench`` needs to reproduce a table.

    Attributes
    ----------
    name : str
        ``paper``, ``demo`` or ``tiny``.
    sim_profile : str
        Simulator profile of the dataset simulated when none is given (``demo-short`` for ``demo``:
        many 1 s scenes with dense traffic, for distinct cars per band).
    n_scenes : int
        Scenes simulated (split 0.6 / 0.2 / 0.2 into train / val / test by the simulator).
    sim_seed : int
        Seed of the simulated dataset.
    labelled_fraction : float
        Share of the training scenes' time segments (half a second each,
        :data:`zendar_baselines.labels.splits.DEFAULT_SEGMENT_FRAMES`) whose manual labels the models
        may see, drawn across all training scenes; everything else is seen only through automatic
        labels. The paper has 10,000 manual and 400,000 automatic labels (2.5 %); a small simulated
        dataset cannot go that low and still hold ``min_labelled_cars`` cars per band, so each config
        takes the scarcest share that does (counted on its training split: docs/baselines.md).
    min_labelled_cars : int
        Distinct labelled cars the labelled part must hold in each range band (near, mid, far);
        fewer stops the run (exit 2) before any training.
    window : int
        K, the latest range-Doppler maps stacked over time as the CNN input (with all antennas:
        ``K * n_rx`` channels).
    width_scale : float
        Multiplies every channel width (1.0 = the published architectures).
    pretrain, finetune, supervised : Schedule
        Pretraining on automatic labels, fine-tuning on manual labels, and supervised-only training
        (epochs at most; ``patience`` for early stopping on the validation loss).
    seeds : int
        Training seeds per row by default (mean ± std over them).
    models : tuple of str
        Architectures to train.
    """

    name: str
    sim_profile: str
    n_scenes: int
    sim_seed: int
    labelled_fraction: float
    window: int
    width_scale: float
    pretrain: Schedule
    finetune: Schedule
    supervised: Schedule
    seeds: int
    models: tuple[str, ...] = field(default=MODEL_NAMES)
    # Last, with a default: results.json of runs made before it was added still read back (verify).
    min_labelled_cars: int = 0

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict (recorded beside every result the config made)."""
        out = asdict(self)
        out["models"] = list(self.models)
        return out


CONFIGS: dict[str, BenchConfig] = {
    "paper": BenchConfig(
        name="paper", sim_profile="paper", n_scenes=27, sim_seed=0, labelled_fraction=0.1, min_labelled_cars=10,
        window=3,
        width_scale=1.0,
        pretrain=Schedule(lr=1e-4, batch_size=8, epochs=100),
        finetune=Schedule(lr=1e-5, batch_size=8, epochs=80),
        supervised=Schedule(lr=1e-4, batch_size=8, epochs=80),
        seeds=3,
    ),
    "demo": BenchConfig(
        name="demo", sim_profile="demo-short", n_scenes=60, sim_seed=0, labelled_fraction=0.1, min_labelled_cars=10,
        window=3,
        width_scale=0.125,
        pretrain=Schedule(lr=1e-3, batch_size=16, epochs=4, patience=2),
        finetune=Schedule(lr=3e-4, batch_size=16, epochs=20, patience=3),
        supervised=Schedule(lr=1e-3, batch_size=16, epochs=60, patience=3),
        seeds=3,
    ),
    "gpu": BenchConfig(
        name="gpu", sim_profile="demo-short", n_scenes=240, sim_seed=0, labelled_fraction=0.1, min_labelled_cars=10,
        window=3,
        width_scale=1.0,
        pretrain=Schedule(lr=1e-3, batch_size=16, epochs=20, patience=4),
        finetune=Schedule(lr=3e-4, batch_size=16, epochs=40, patience=5),
        supervised=Schedule(lr=1e-3, batch_size=16, epochs=240, patience=5),
        seeds=3,
    ),
    "tiny": BenchConfig(
        name="tiny", sim_profile="tiny", n_scenes=15, sim_seed=0, labelled_fraction=0.25, min_labelled_cars=1,
        window=2,
        width_scale=0.25,
        pretrain=Schedule(lr=1e-3, batch_size=16, epochs=20, patience=5),
        finetune=Schedule(lr=3e-4, batch_size=16, epochs=40, patience=5),
        supervised=Schedule(lr=1e-3, batch_size=16, epochs=120, patience=5),
        seeds=1,
    ),
}


def get_config(name: str) -> BenchConfig:
    """The configuration called ``name``; ZendarError naming the choices otherwise."""
    try:
        return CONFIGS[name]
    except (KeyError, TypeError):
        raise ZendarError(f"unknown config {name!r}: choose one of {', '.join(CONFIGS)}") from None
