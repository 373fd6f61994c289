"""Training: the masked loss, learning a hand-made task, the epoch chosen by validation, early stopping,
determinism, resume, init_from, prediction."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch
from torch.utils.data import ConcatDataset

from zendar_dataset.errors import ZendarError

from zendar_baselines.cnn import checkpoints
from zendar_baselines.cnn.checkpoints import MANIFEST_NAME, load_checkpoint
from zendar_baselines.bench.configs import Schedule
from zendar_baselines.cnn.mask_frames import MaskFrames
from zendar_baselines.cnn.training import (
    checkpoint_path,
    hold_out_tail,
    masked_bce,
    positive_class_weight,
    predict_masks,
    seed_everything,
    train,
)

from tests.baselines.tiny_mask_model import TinyMaskNet, moving_target_task

SCHEDULE = Schedule(lr=1e-2, batch_size=8, epochs=2)


pytestmark = pytest.mark.usefixtures("one_thread")


@pytest.fixture(scope="module")
def task_data():
    inputs, masks = moving_target_task(48, seed=0)
    return MaskFrames(inputs, masks)


def _model(seed=0, in_channels=2):
    seed_everything(seed)
    return TinyMaskNet(in_channels)


def _weights(model):
    return {name: tensor.clone() for name, tensor in model.state_dict().items()}


def _assert_same_weights(a, b):
    assert a.keys() == b.keys()
    for name in a:
        assert torch.equal(a[name], b[name]), name


def test_masked_bce_by_hand():
    logits = torch.tensor([0.5, -1.0, 2.0, 7.0]).reshape(1, 1, 1, 4)
    targets = torch.tensor([1, 0, 2, 2], dtype=torch.uint8).reshape(1, 1, 4)
    loss_sum, n_labelled = masked_bce(logits, targets, pos_weight=3.0)
    # moving: -3 log σ(0.5) = 3 log(1 + e^-0.5); background: -log(1 - σ(-1)) = log(1 + e^-1).
    expected = 3 * math.log(1 + math.exp(-0.5)) + math.log(1 + math.exp(-1.0))
    assert float(n_labelled) == 2.0
    assert float(loss_sum) == pytest.approx(expected, rel=1e-6)


def test_uncertain_cells_give_no_gradient():
    logits = torch.randn(2, 1, 3, 4, requires_grad=True)
    all_uncertain = torch.full((2, 3, 4), 2, dtype=torch.uint8)
    loss_sum, n_labelled = masked_bce(logits, all_uncertain, pos_weight=10.0)
    loss_sum.backward()
    assert float(n_labelled) == 0.0 and float(loss_sum.detach()) == 0.0
    assert torch.count_nonzero(logits.grad) == 0

    mixed = torch.zeros((2, 3, 4), dtype=torch.uint8)
    mixed[0, 1, 2] = 1
    mixed[1, 2, :] = 2
    with torch.no_grad():
        poisoned = logits.detach().clone()
        poisoned[1, 0, 2, :] = float("nan")  # a non-finite logit in ignored cells stays out of the sum
    poisoned.requires_grad_(True)
    loss_sum, _ = masked_bce(poisoned, mixed, pos_weight=10.0)
    loss_sum.backward()
    assert math.isfinite(float(loss_sum.detach()))
    assert torch.all(poisoned.grad[1, 0, 2, :] == 0)
    assert torch.all(poisoned.grad[0] != 0)


def test_masked_bce_refuses_misshapen_logits():
    with pytest.raises(ZendarError, match=r"logits \(2, 3, 4\)"):
        masked_bce(torch.zeros(2, 3, 4), torch.zeros(2, 3, 4, dtype=torch.uint8), 1.0)


def test_positive_class_weight_by_hand():
    masks = np.zeros((4, 5, 5), dtype=np.uint8)
    masks[:, 0, 0] = 1  # 4 moving cells
    masks[:, 1, :] = 2  # 20 uncertain, left out; 76 background
    data = MaskFrames(np.zeros((4, 1, 5, 5), dtype=np.float32), masks)
    assert positive_class_weight(data) == pytest.approx(math.sqrt(76 / 4))
    assert positive_class_weight(MaskFrames(np.zeros((4, 1, 5, 5), np.float32), np.zeros((4, 5, 5), np.uint8))) == 1.0


def _f1(probabilities, masks):
    labelled = masks != 2
    predicted = (probabilities > 0.5) & labelled
    truth = masks == 1
    tp = np.count_nonzero(predicted & truth)
    return 2 * tp / (np.count_nonzero(predicted) + np.count_nonzero(truth))


def test_small_model_learns_the_moving_target_task(tmp_path):
    inputs, masks = moving_target_task(128, seed=1)
    held_inputs, held_masks = moving_target_task(64, seed=2)
    model = _model(0)
    before = _f1(predict_masks(model, held_inputs, 32, "cpu"), held_masks)
    result = train(model, MaskFrames(inputs, masks), Schedule(lr=1e-2, batch_size=16, epochs=20),
                   seed=0, out_dir=tmp_path, progress=False)
    assert result.epoch_losses[-1] < 0.3 * result.epoch_losses[0]
    after = _f1(predict_masks(model, held_inputs, 32, "cpu"), held_masks)
    assert before < 0.2 and after > 0.8, (before, after)


def test_same_seed_same_weights_other_seed_other_weights(tmp_path, task_data):
    runs = {}
    for name, seed in (("a", 5), ("b", 5), ("c", 6)):
        model = _model(0)
        result = train(model, task_data, SCHEDULE, seed=seed, out_dir=tmp_path / name, progress=False)
        runs[name] = (_weights(model), result.epoch_losses)
    _assert_same_weights(runs["a"][0], runs["b"][0])
    assert runs["a"][1] == runs["b"][1]
    assert not torch.equal(runs["a"][0]["features.weight"], runs["c"][0]["features.weight"])


def test_resume_equals_an_uninterrupted_run(tmp_path, task_data):
    uninterrupted = _model(0)
    whole = train(uninterrupted, task_data, SCHEDULE, seed=1, out_dir=tmp_path / "whole", progress=False)

    first = train(_model(0), task_data, Schedule(SCHEDULE.lr, SCHEDULE.batch_size, 1),
                  seed=1, out_dir=tmp_path / "cut", progress=False)
    assert first.resumed_from_epoch == 0 and len(first.epoch_losses) == 1
    # Scramble the global generators as another program would before the restart.
    torch.manual_seed(1234)
    np.random.seed(99)
    resumed_model = _model(0)
    resumed = train(resumed_model, task_data, SCHEDULE, seed=1, out_dir=tmp_path / "cut", progress=False)
    assert resumed.resumed_from_epoch == 1
    _assert_same_weights(_weights(uninterrupted), _weights(resumed_model))
    assert resumed.epoch_losses == whole.epoch_losses
    assert resumed.checkpoint_path == checkpoint_path(tmp_path / "cut", 2)

    again_model = _model(0)
    again = train(again_model, task_data, SCHEDULE, seed=1, out_dir=tmp_path / "cut", progress=False)
    assert again.resumed_from_epoch == 2 and again.epoch_losses == whole.epoch_losses
    _assert_same_weights(_weights(uninterrupted), _weights(again_model))


def test_checkpoint_the_manifest_does_not_vouch_for_is_recomputed(tmp_path, task_data, monkeypatch):
    reference = _model(0)
    train(reference, task_data, SCHEDULE, seed=2, out_dir=tmp_path / "ref", progress=False)
    out = tmp_path / "run"
    # The process dies between renaming epoch 2 into place and recording it in the manifest (so
    # epoch 1, removed only once epoch 2 is vouched for, is still there).
    real_write = checkpoints.write_text_atomic

    def dying_write(path, text, *args, **kwargs):
        if path.name == MANIFEST_NAME and "epoch-0002.pt" in text:
            raise KeyboardInterrupt
        return real_write(path, text, *args, **kwargs)

    monkeypatch.setattr(checkpoints, "write_text_atomic", dying_write)
    with pytest.raises(KeyboardInterrupt):
        train(_model(0), task_data, SCHEDULE, seed=2, out_dir=out, progress=False)
    monkeypatch.undo()
    assert "epoch-0002.pt" not in json.loads((out / MANIFEST_NAME).read_text())
    assert (out / "epoch-0002.pt").is_file()
    model = _model(0)
    result = train(model, task_data, SCHEDULE, seed=2, out_dir=out, progress=False)
    assert result.resumed_from_epoch == 1
    _assert_same_weights(_weights(reference), _weights(model))
    load_checkpoint(out / "epoch-0002.pt")  # vouched for again


def test_out_dir_of_another_run_is_refused(tmp_path, task_data):
    train(_model(0), task_data, SCHEDULE, seed=3, out_dir=tmp_path, progress=False)
    with pytest.raises(ZendarError, match=r"another run \(differs in seed\)"):
        train(_model(0), task_data, SCHEDULE, seed=4, out_dir=tmp_path, progress=False)
    with pytest.raises(ZendarError, match=r"differs in initial_weights_sha256"):
        train(_model(1), task_data, SCHEDULE, seed=3, out_dir=tmp_path, progress=False)


def test_init_from_copies_weights_and_starts_a_fresh_optimizer(tmp_path, task_data):
    pretrained = _model(0)
    pre = train(pretrained, task_data, SCHEDULE, seed=0, out_dir=tmp_path / "pre", progress=False)
    fine = _model(1)
    assert not torch.equal(fine.features.weight, pretrained.features.weight)
    # lr 0: Adam leaves the weights where init_from put them.
    result = train(fine, task_data, Schedule(lr=0.0, batch_size=8, epochs=1), seed=0,
                   out_dir=tmp_path / "fine", init_from=pre.checkpoint_path, progress=False)
    _assert_same_weights(_weights(pretrained), _weights(fine))
    checkpoint = load_checkpoint(result.checkpoint_path)
    steps_per_epoch = math.ceil(len(task_data) / 8)
    assert checkpoint["optimizer_state"]["state"][0]["step"] == steps_per_epoch  # not 3 epochs' worth
    assert checkpoint["config"]["init_from"]["epoch"] == 2


def test_init_from_another_architecture_names_both(tmp_path, task_data):
    pre = train(_model(0), task_data, SCHEDULE, seed=0, out_dir=tmp_path / "pre", progress=False)
    other = TinyMaskNet(in_channels=2, width=4)
    with pytest.raises(ZendarError) as excinfo:
        train(other, task_data, SCHEDULE, seed=0, out_dir=tmp_path / "fine", init_from=pre.checkpoint_path, progress=False)
    message = str(excinfo.value)
    assert str(pre.checkpoint_path) in message and '"width_scale": 1.0' in message and '"width_scale": 0.5' in message


def test_bad_schedules_are_refused(tmp_path, task_data):
    for schedule, match in ((Schedule(1e-3, 8, 0), "epochs"), (Schedule(1e-3, 0, 1), "batch_size"),
                            (Schedule(float("nan"), 8, 1), "lr")):
        with pytest.raises(ZendarError, match=match):
            train(_model(0), task_data, schedule, seed=0, out_dir=tmp_path, progress=False)


def test_progress_bar_shows_epoch_and_loss(tmp_path, task_data, capsys):
    train(_model(0), task_data, SCHEDULE, seed=0, out_dir=tmp_path, description="tiny", progress=True)
    err = capsys.readouterr().err
    assert "tiny epoch 2/2" in err and "loss=" in err


def test_predict_masks_is_the_sigmoid_of_the_logits():
    model = _model(3)
    model.train()
    inputs, _ = moving_target_task(5, seed=4)
    probabilities = predict_masks(model, inputs, batch_size=2, device="cpu")
    assert probabilities.shape == (5, 16, 8) and probabilities.dtype == np.float32
    with torch.no_grad():
        logits = model(torch.from_numpy(inputs))[:, 0].numpy()
    np.testing.assert_allclose(probabilities, 1 / (1 + np.exp(-logits)), rtol=1e-5, atol=1e-7)
    assert model.training


def test_densenet_37_trains_and_comes_back_from_its_checkpoint(tmp_path, task_data):
    from zendar_baselines.cnn.models import build_model

    seed_everything(0)
    model = build_model("densenet-37", in_channels=2, width_scale=0.25)
    result = train(model, task_data, Schedule(lr=1e-3, batch_size=16, epochs=1), seed=0, out_dir=tmp_path, progress=False)
    assert math.isfinite(result.epoch_losses[0])
    rebuilt = build_model("densenet-37", in_channels=2, width_scale=0.25)
    checkpoint = load_checkpoint(result.checkpoint_path, expected_architecture=rebuilt.architecture, model=rebuilt)
    assert checkpoint["architecture"] == {"name": "densenet-37", "in_channels": 2, "width_scale": 0.25}
    inputs, _ = moving_target_task(4, seed=9)
    # Eval mode uses the batch-norm running statistics: equal outputs mean the buffers came back too.
    np.testing.assert_array_equal(predict_masks(rebuilt, inputs, 4), predict_masks(model, inputs, 4))
    with pytest.raises(ZendarError, match="densenet-67"):
        load_checkpoint(result.checkpoint_path, expected_architecture={**rebuilt.architecture, "name": "densenet-67"})


def test_training_and_prediction_run_channels_last_and_agree_with_an_nchw_forward(tmp_path, task_data):
    """The layout is a speed choice: a fresh NCHW model loaded from the checkpoint predicts what
    ``predict_masks`` does, to float32 rounding."""
    from zendar_baselines.cnn.models import build_model

    seed_everything(0)
    model = build_model("densenet-37", in_channels=2, width_scale=0.25)
    result = train(model, task_data, Schedule(lr=1e-3, batch_size=16, epochs=1), seed=0, out_dir=tmp_path, progress=False)
    convolutions = [p for p in model.parameters() if p.dim() == 4]
    assert convolutions and all(p.is_contiguous(memory_format=torch.channels_last) for p in convolutions)
    nchw = build_model("densenet-37", in_channels=2, width_scale=0.25)
    load_checkpoint(result.checkpoint_path, expected_architecture=nchw.architecture, model=nchw)
    assert all(p.is_contiguous() for p in nchw.parameters())
    inputs, _ = moving_target_task(4, seed=9)
    with torch.no_grad():
        logits = nchw.eval()(torch.from_numpy(inputs))[:, 0]
    np.testing.assert_allclose(predict_masks(nchw, inputs, 4), torch.sigmoid(logits).numpy(), rtol=1e-4, atol=1e-6)


# --- validation: the epoch chosen, early stopping, what stays on disk ---------------------------


class BiasOnly(torch.nn.Module):
    """Logit = one learned bias for every cell: its loss on any mask is known in closed form."""

    def __init__(self) -> None:
        super().__init__()
        self.architecture = {"name": "bias-only", "in_channels": 1, "width_scale": 1.0}
        self.bias = torch.nn.Parameter(torch.zeros(1))

    def forward(self, inputs):
        return self.bias.view(1, 1, 1, 1).expand(inputs.shape[0], 1, *inputs.shape[2:])


N_CELLS = 50 * 20
VALIDATION_MOVING = 47  # of the labelled cells; the validation masks' positive weight is sqrt(953 / 47)


def _bias_task(n_samples=4):
    """Training masks all background (the bias only falls: ~0.5 per Adam step of lr 0.5), and validation
    masks 4.7 % moving with an uncertain row (left out). Weighted by the validation masks' own positive
    weight w = sqrt(953 / 47), the validation loss is least where sigmoid(b) = w q / (w q + 1 - q), at
    b = -1.50 (epoch 3), and rises after; weighted by the training masks' (1.0) it would be least at
    b = logit(0.047) = -3.01 (epoch 6)."""
    inputs = np.zeros((n_samples, 1, 50, 20), np.float32)
    train_masks = np.zeros((n_samples, 50, 20), np.uint8)
    validation_masks = np.zeros((n_samples, 51, 20), np.uint8)
    validation_masks.reshape(n_samples, -1)[:, :VALIDATION_MOVING] = 1
    validation_masks[:, 50, :] = 2
    validation_inputs = np.zeros((n_samples, 1, 51, 20), np.float32)
    return MaskFrames(inputs, train_masks), MaskFrames(validation_inputs, validation_masks)


def _validation_loss_by_hand(bias: float) -> float:
    q = VALIDATION_MOVING / N_CELLS
    weight = math.sqrt((N_CELLS - VALIDATION_MOVING) / VALIDATION_MOVING)
    p = 1 / (1 + math.exp(-bias))
    # Summed over cells and divided by their number: the mean per labelled cell.
    return -(weight * q * math.log(p) + (1 - q) * math.log(1 - p))


BIAS_SCHEDULE = Schedule(lr=0.5, batch_size=4, epochs=10, patience=2)


def test_the_epoch_of_least_validation_loss_is_chosen_and_training_stops_after_patience(tmp_path):
    data, validation = _bias_task()
    result = train(BiasOnly(), data, BIAS_SCHEDULE, seed=0, out_dir=tmp_path, validation=validation, progress=False)
    assert result.best_epoch == 3 and result.stopped_early
    assert len(result.epoch_losses) == len(result.validation_losses) == 5  # epochs 4 and 5 did not improve
    assert result.checkpoint_path == checkpoint_path(tmp_path, 3)
    assert result.last_checkpoint_path == checkpoint_path(tmp_path, 5)
    # Only the chosen and the last epoch stay, both vouched for by the manifest.
    assert sorted(p.name for p in tmp_path.glob("epoch-*.pt")) == ["epoch-0003.pt", "epoch-0005.pt"]
    assert sorted(json.loads((tmp_path / MANIFEST_NAME).read_text())) == ["epoch-0003.pt", "epoch-0005.pt"]
    best, last = load_checkpoint(result.checkpoint_path), load_checkpoint(result.last_checkpoint_path)
    # The validation loss recorded is the masked loss of the checkpoint's own weights (eval mode).
    for checkpoint in (best, last):
        bias = float(checkpoint["model_state"]["bias"])
        recorded = checkpoint["validation_losses"][checkpoint["epoch"] - 1]
        assert recorded == pytest.approx(_validation_loss_by_hand(bias), rel=1e-5)
    assert -2.0 < float(best["model_state"]["bias"]) < -1.0 and last["best_epoch"] == 3
    assert last["validation_losses"] == list(result.validation_losses)
    losses = result.validation_losses
    assert losses[0] > losses[1] > losses[2] < losses[3] < losses[4]


def test_resuming_keeps_the_choice_of_an_uninterrupted_run(tmp_path):
    data, validation = _bias_task()
    whole = train(BiasOnly(), data, BIAS_SCHEDULE, seed=0, out_dir=tmp_path / "whole", validation=validation,
                  progress=False)
    cut = Schedule(BIAS_SCHEDULE.lr, BIAS_SCHEDULE.batch_size, 4, BIAS_SCHEDULE.patience)
    first = train(BiasOnly(), data, cut, seed=0, out_dir=tmp_path / "cut", validation=validation, progress=False)
    assert first.best_epoch == 3 and not first.stopped_early and len(first.epoch_losses) == 4
    resumed = train(BiasOnly(), data, BIAS_SCHEDULE, seed=0, out_dir=tmp_path / "cut", validation=validation,
                    progress=False)
    assert resumed.resumed_from_epoch == 4
    assert (resumed.best_epoch, resumed.epoch_losses, resumed.validation_losses, resumed.stopped_early) == (
        whole.best_epoch, whole.epoch_losses, whole.validation_losses, whole.stopped_early)
    finished = train(BiasOnly(), data, BIAS_SCHEDULE, seed=0, out_dir=tmp_path / "cut", validation=validation,
                     progress=False)
    assert finished.resumed_from_epoch == 5 and finished.validation_losses == whole.validation_losses
    for result in (resumed, finished):
        assert torch.equal(load_checkpoint(result.checkpoint_path)["model_state"]["bias"],
                           load_checkpoint(whole.checkpoint_path)["model_state"]["bias"])


def test_without_validation_the_last_epoch_is_chosen_and_patience_is_refused(tmp_path, task_data):
    result = train(_model(0), task_data, SCHEDULE, seed=0, out_dir=tmp_path / "plain", progress=False)
    assert result.best_epoch == 2 and result.checkpoint_path == result.last_checkpoint_path
    assert result.validation_losses == () and not result.stopped_early
    with pytest.raises(ZendarError, match="give validation data"):
        train(_model(0), task_data, Schedule(1e-2, 8, 2, patience=1), seed=0, out_dir=tmp_path / "p", progress=False)
    with pytest.raises(ZendarError, match="patience must be None or a positive integer"):
        train(_model(0), task_data, Schedule(1e-2, 8, 2, patience=0), seed=0, out_dir=tmp_path / "q",
              validation=task_data, progress=False)


def test_validation_masks_without_a_labelled_cell_are_refused(tmp_path, task_data):
    inputs, _ = moving_target_task(4, seed=5)
    uncertain = MaskFrames(inputs, np.full((4, 16, 8), 2, np.uint8))
    with pytest.raises(ZendarError, match="validation masks have no labelled cell"):
        train(_model(0), task_data, SCHEDULE, seed=0, out_dir=tmp_path, validation=uncertain, progress=False)


def test_hold_out_tail_keeps_a_gap_between_the_parts():
    parts = ConcatDataset([MaskFrames(np.zeros((12, 1, 2, 2), np.float32), np.zeros((12, 2, 2), np.uint8), window=3),
                           MaskFrames(np.zeros((7, 1, 2, 2), np.float32), np.zeros((7, 2, 2), np.uint8), window=3)])
    kept, held_out = hold_out_tail(parts, 0.2, gap=2)
    # One sample per map (the first windows padded): part 0 has 12, 3 held out (9-11), samples 7 and 8
    # dropped; part 1 has 7, 2 held out (5, 6), samples 3 and 4 dropped.
    assert [list(p.indices) for p in kept.datasets] == [list(range(7)), [0, 1, 2]]
    assert [list(p.indices) for p in held_out.datasets] == [[9, 10, 11], [5, 6]]
    # No map in both: kept windows end at map 6 of part 0, held-out ones start at map 9 - 3 + 1 = 7.
    assert max(kept.datasets[0].indices) < min(held_out.datasets[0].indices) - 3 + 1
    with pytest.raises(ZendarError, match="part 1 has 7 samples, too few"):
        hold_out_tail(parts, 0.6, gap=2)


# --- reproducibility ----------------------------------------------------------------------------


class _SettingsSpy(TinyMaskNet):
    """Records torch's thread count and deterministic mode at every forward."""

    seen: set

    def forward(self, inputs):
        self.seen.add((torch.get_num_threads(), torch.are_deterministic_algorithms_enabled(),
                       torch.utils.deterministic.fill_uninitialized_memory))
        return super().forward(inputs)


def test_training_runs_deterministic_with_a_fixed_thread_count_and_restores_the_settings(tmp_path, task_data):
    from zendar_baselines.cnn.training import TRAINING_THREADS

    before = torch.get_num_threads()
    fill_before = torch.utils.deterministic.fill_uninitialized_memory
    assert fill_before is True  # torch's default: the check below sees a restore, not a value left behind
    seed_everything(0)
    spy = _SettingsSpy(2)
    spy.seen = set()
    assert not torch.are_deterministic_algorithms_enabled()
    train(spy, task_data, SCHEDULE, seed=0, out_dir=tmp_path, validation=task_data, progress=False)
    assert spy.seen == {(TRAINING_THREADS, True, False)}
    assert torch.get_num_threads() == before and not torch.are_deterministic_algorithms_enabled()
    assert torch.utils.deterministic.fill_uninitialized_memory is fill_before


@pytest.mark.parametrize("name", ["fpn-resnet34", "densenet-37", "densenet-67"])
def test_no_op_of_the_models_reads_uninitialised_memory(tmp_path, monkeypatch, name):
    """Training and predicting without deterministic mode's NaN filling of new tensors (what makes it
    faster) gives bit for bit the weights and probabilities of a run with it: a op that read memory it
    never wrote would read NaN in one run and leftovers in the other."""
    from zendar_baselines.cnn import training
    from zendar_baselines.cnn.models import build_model

    inputs = np.random.default_rng(3).standard_normal((8, 6, 32, 16)).astype(np.float32)
    masks = np.random.default_rng(4).integers(0, 3, (8, 32, 16)).astype(np.uint8)
    data = MaskFrames(inputs, masks)
    runs = []
    for fill in (True, False):
        monkeypatch.setattr(training, "FILL_UNINITIALIZED_MEMORY", fill)
        seed_everything(0)
        model = build_model(name, 6, 0.125)
        train(model, data, Schedule(lr=1e-3, batch_size=4, epochs=1), seed=0, out_dir=tmp_path / str(fill), progress=False)
        runs.append((_weights(model), predict_masks(model, inputs, batch_size=4)))
    _assert_same_weights(runs[0][0], runs[1][0])
    np.testing.assert_array_equal(runs[0][1], runs[1][1])
    assert np.isfinite(runs[1][1]).all()


def test_the_weights_do_not_depend_on_the_callers_thread_count(tmp_path, task_data):
    runs = []
    for threads in (1, 2):
        torch.set_num_threads(threads)
        model = _model(0)
        train(model, task_data, SCHEDULE, seed=5, out_dir=tmp_path / str(threads), validation=task_data, progress=False)
        runs.append(_weights(model))
    torch.set_num_threads(1)
    _assert_same_weights(*runs)
