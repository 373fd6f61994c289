"""A row's training records: the validation data that chooses its checkpoints (the validation split, or
held-out labelled frames with a warning), ``checkpoint.json`` and ``curves.json``."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from torch.utils.data import ConcatDataset

from zendar_dataset.errors import ZendarError

from zendar_baselines.bench import steps
from zendar_baselines.bench.context import RowSeed
from zendar_baselines.cnn.mask_frames import MaskFrames
from zendar_baselines.cnn.schedule import Schedule
from zendar_baselines.cnn.training import seed_everything, train

from tests.baselines.tiny_mask_model import TinyMaskNet, moving_target_task


pytestmark = pytest.mark.usefixtures("one_thread")


class _Splits:
    def __init__(self, **splits: list[str]) -> None:
        self.splits = splits

    def scene_ids(self, split: str) -> list[str]:
        return list(self.splits.get(split, []))


def _scene_frames(n_maps: int, seed: int) -> MaskFrames:
    inputs, masks = moving_target_task(n_maps, seed=seed)
    return MaskFrames(inputs[:, :1], masks, window=2)  # one antenna, K = 2: 2 channels, as TinyMaskNet(2)


def test_without_validation_scenes_labelled_frames_are_held_out_with_a_warning(capsys):
    run = SimpleNamespace(dataset=_Splits(train=["scene-0000", "scene-0001"], val=[], test=["scene-0002"]),
                          root=Path("/data/set"), config=SimpleNamespace(window=2))
    labels = SimpleNamespace(split=SimpleNamespace(labelled=["scene-0000"]), validation_dir=None)
    labelled = ConcatDataset([_scene_frames(21, 0), _scene_frames(11, 1)])  # 21 and 11 windows (the first padded)
    kept, validation, record = steps.validation_frames(run, labels, labelled)
    assert "warning: /data/set has no validation scenes" in capsys.readouterr().err
    assert record == {"source": "held-out labelled training frames", "scenes": ["scene-0000"],
                      "fraction": steps.HOLD_OUT_FRACTION, "window_stride": 2, "n_samples": 3 + 2}
    # The last 20 % of each part is held out, one window (K - 1) apart from what trains; of it every
    # K-th window validates (windows that share no map).
    assert [list(part.indices) for part in kept.datasets] == [list(range(15)), list(range(7))]
    held_out = [[part.dataset.indices[i] for i in part.indices] for part in validation.datasets]
    assert held_out == [[16, 18, 20], [8, 10]]


def test_the_validation_masks_refuse_a_scene_of_the_test_split(tmp_path):
    run = SimpleNamespace(dataset=_Splits(val=["scene-0003"], test=["scene-0003", "scene-0004"]), root=Path("/d"))
    with pytest.raises(ZendarError, match=r"\['scene-0003'\] are in both the val and the test split"):
        steps.write_validation_masks(run, tmp_path)
    assert list(tmp_path.iterdir()) == []


def test_checkpoint_json_and_curves_json_record_every_epoch_of_every_phase(tmp_path):
    data = ConcatDataset([_scene_frames(25, 2)])
    validation = ConcatDataset([_scene_frames(9, 3)])
    seed_everything(0)
    pretrain = train(TinyMaskNet(2), data, Schedule(1e-2, 8, 3), seed=0, out_dir=tmp_path / "pretrain",
                     validation=validation, progress=False)
    seed_everything(0)
    fine = train(TinyMaskNet(2), data, Schedule(1e-3, 8, 2), seed=0, out_dir=tmp_path / "fine-tune",
                 init_from=pretrain.checkpoint_path, validation=validation, progress=False)
    record = {"source": "val split", "scenes": ["scene-0003"], "n_samples": len(validation)}
    steps.write_training_records(tmp_path, RowSeed("densenet-37", True, 0), {"pretrain": pretrain, "fine-tune": fine}, record)

    checkpoint = json.loads((tmp_path / steps.CHECKPOINT_RECORD).read_text())
    assert checkpoint["validation"] == record
    assert list(checkpoint["phases"]) == ["pretrain", "fine-tune"]
    for name, result in (("pretrain", pretrain), ("fine-tune", fine)):
        phase = checkpoint["phases"][name]
        assert phase["best_epoch"] == result.best_epoch
        assert phase["best_epoch"] == int(np.argmin(result.validation_losses)) + 1
        assert phase["checkpoint"] == f"{name}/epoch-{result.best_epoch:04d}.pt"
        assert phase["validation_losses"] == list(result.validation_losses)
        assert phase["train_losses"] == list(result.epoch_losses)
    assert steps.final_checkpoint(tmp_path) == fine.checkpoint_path
    assert checkpoint["epoch_losses"] == list(fine.epoch_losses)

    curves = json.loads((tmp_path / steps.CURVES_FILE).read_text())
    assert (curves["row"], curves["seed"], curves["validation"]) == ("densenet-37-pretrained", 0, "val split")
    assert [(phase["phase"], len(phase["epochs"])) for phase in curves["phases"]] == [("pretrain", 3), ("fine-tune", 2)]
    for phase, result in zip(curves["phases"], (pretrain, fine)):
        assert [entry["epoch"] for entry in phase["epochs"]] == list(range(1, len(result.epoch_losses) + 1))
        assert [entry["train"] for entry in phase["epochs"]] == list(result.epoch_losses)
        assert [entry["validation"] for entry in phase["epochs"]] == list(result.validation_losses)
