"""The CPU configs' schedules: comparable budgets for the supervised-only and pretrained rows, early stopping."""

from __future__ import annotations

import pytest

from zendar_baselines.bench.configs import get_config


@pytest.mark.parametrize("name", ["demo", "gpu", "tiny"])
def test_supervised_rows_may_see_as_many_windows_as_pretraining_plus_fine_tuning(name):
    config = get_config(name)
    labelled_windows = 100.0  # any L: every training scene holds about L / labelled_fraction windows
    pretrained = (config.pretrain.epochs * labelled_windows / config.labelled_fraction
                  + config.finetune.epochs * labelled_windows)
    supervised = config.supervised.epochs * labelled_windows
    assert supervised == pytest.approx(pretrained)
    # Same optimiser settings as the phase that also starts from fresh weights, and the same patience
    # as the other phase on the manual labels.
    assert (config.supervised.lr, config.supervised.batch_size) == (config.pretrain.lr, config.pretrain.batch_size)
    assert config.supervised.patience == config.finetune.patience


@pytest.mark.parametrize("name", ["demo", "gpu", "tiny"])
def test_cpu_configs_stop_early_on_the_validation_loss(name):
    config = get_config(name)
    for schedule in (config.pretrain, config.finetune, config.supervised):
        assert schedule.patience is not None and 1 <= schedule.patience < schedule.epochs
