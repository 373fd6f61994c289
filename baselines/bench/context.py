"""The frozen records a ``zendar-bench`` run passes to its steps instead of long argument lists."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from zendar_dataset.format.reader import DatasetIndex, open_dataset

from zendar_baselines.bench.configs import BenchConfig
from zendar_baselines.bench.scoring import ScoringScenes
from zendar_baselines.classical.kept_scenes import KeptScenes
from zendar_baselines.cnn.input_channels import InputChannels
from zendar_baselines.code_version import code_version
from zendar_baselines.fingerprints import dataset_fingerprint
from zendar_baselines.labels.splits import SemiSupervisedSplit

#: Under the run directory: memory-mapped log-power maps shared by every row's training.
INPUTS_DIR = "inputs"

#: This process's kept scenes, per dataset (root and fingerprint) and use: the training and validation
#: scenes (:meth:`RunContext.kept_scenes`) and the test scenes (:meth:`RunContext.scoring_scenes`).
_KEPT_SCENES: dict[tuple[Path, str, str], KeptScenes] = {}


@dataclass(frozen=True)
class RunContext:
    """One run: the dataset (opened and fingerprinted once), the configuration and where results go.

    Attributes
    ----------
    root : Path
        The dataset root.
    dataset : DatasetIndex
        The dataset, opened once for every step.
    fingerprint : str
        SHA-256 of its ``dataset.json`` (:func:`zendar_baselines.fingerprints.dataset_fingerprint`).
    config : BenchConfig
    run_path : Path
        The run directory (``--out``).
    device : str
        ``cpu`` or ``cuda``: where the CNNs run.
    code_version : str
        :func:`zendar_baselines.code_version.code_version`.
    progress : bool
        Whether the steps show progress bars (off in worker processes, whose bars would interleave).
    """

    root: Path
    dataset: DatasetIndex
    fingerprint: str
    config: BenchConfig
    run_path: Path
    device: str
    code_version: str
    progress: bool = True

    @classmethod
    def open(cls, root: Path, config: BenchConfig, run_path: Path, device: str,
             dataset: DatasetIndex | None = None) -> RunContext:
        """The context of a run on ``root`` (opened here unless ``dataset`` is given)."""
        dataset = open_dataset(str(root)) if dataset is None else dataset
        return cls(Path(root), dataset, dataset_fingerprint(dataset), config, Path(run_path), device, code_version())

    @property
    def inputs_dir(self) -> Path:
        """Where the training scenes' log-power maps are cached."""
        return self.run_path / INPUTS_DIR

    def kept_scenes(self) -> KeptScenes:
        """This process's training and validation scenes, opened once for every seed's passes: the
        training windows and the chain fit (:class:`~zendar_baselines.classical.kept_scenes.KeptScenes`)."""
        key = (self.root, self.fingerprint, "train+val")
        if key not in _KEPT_SCENES:
            scene_ids = [s for split in ("train", "val") if split in self.dataset.splits for s in self.dataset.scene_ids(split)]
            _KEPT_SCENES[key] = KeptScenes(self.dataset, scene_ids)
        return _KEPT_SCENES[key]

    def scoring_scenes(self) -> ScoringScenes:
        """This process's test scenes, opened once for every seed's scoring
        (:class:`~zendar_baselines.bench.scoring.ScoringScenes`)."""
        key = (self.root, self.fingerprint, "test")
        if key not in _KEPT_SCENES:
            _KEPT_SCENES[key] = ScoringScenes(self.dataset)
        return _KEPT_SCENES[key]

    def step_inputs(self) -> dict[str, Any]:
        """What every step's cache key starts from: the configuration, the dataset and the code."""
        return {"config": self.config.to_json(), "dataset": self.fingerprint, "code_version": self.code_version}


def close_kept_scenes() -> None:
    """Close every scene :meth:`RunContext.kept_scenes` and :meth:`RunContext.scoring_scenes` kept open
    in this process (at the end of a run, and in the main process before the seed workers start)."""
    for scenes in _KEPT_SCENES.values():
        scenes.close()
    _KEPT_SCENES.clear()


@dataclass(frozen=True)
class TrainingLabels:
    """The targets the CNN rows train on.

    Attributes
    ----------
    split : SemiSupervisedSplit
        The labelled and unlabelled parts of the training scenes.
    auto_dir : Path
        The ``autolabels`` step (automatic masks of every training scene under ``store/``).
    masks_dir : Path
        The ``label_masks`` step (manual-label masks of the labelled part under ``store/``).
    validation_dir : Path
        The ``validation_masks`` step (manual-label masks of the validation scenes under ``store/``),
        which choose the checkpoints.
    """

    split: SemiSupervisedSplit
    auto_dir: Path
    masks_dir: Path
    validation_dir: Path


@dataclass(frozen=True)
class RowSeed:
    """One seed of one CNN row of Table 1 (``inputs``: the optional input channels of an ablation row;
    the paper's input by default)."""

    model_name: str
    pretrained: bool
    seed: int
    inputs: InputChannels = InputChannels()

    @property
    def row_key(self) -> str:
        """``<model>-pretrained`` or ``<model>-supervised``: the row's directory under ``rows/``."""
        return f"{self.model_name}-{'pretrained' if self.pretrained else 'supervised'}"
