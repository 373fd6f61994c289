"""The CNN detectors: parameter counts against the published networks, layer counts, shapes, training
from scratch, and a learning check that needs the time axis."""

from __future__ import annotations

import math

import pytest
import torch
import torch.nn.functional as F
from torch import nn

from zendar_baselines.bench import configs
from zendar_baselines.cnn.models import MODEL_NAMES, build_model, parameter_count
from zendar_baselines.cnn.models.common import GlobalPoolClassifier
from zendar_baselines.cnn.models.densenet import DenseNetBackbone
from zendar_baselines.cnn.models.fpn import FeaturePyramid
from zendar_baselines.cnn.models.resnet import ResNet34Backbone
from zendar_dataset.errors import ZendarError

EXPECTED_LAYERS = {"fpn-resnet34": 34, "densenet-37": 37, "densenet-67": 67}
# Weighted layers that the published counts leave out: ResNet's shortcut projections, the
# pyramid's lateral and output convolutions, the FPN head's per-level 3x3 convolutions, and the
# zoom-out projections (counted with the logit convolution as the one classifier layer).
UNCOUNTED_PARTS = (".downsample.", "fpn.", "head.", "zoom.")


pytestmark = pytest.mark.usefixtures("one_thread")


def weighted_layers(model: nn.Module) -> int:
    """Conv2d and Linear modules outside the parts the published layer counts leave out."""
    return sum(
        1
        for name, module in model.named_modules()
        if isinstance(module, (nn.Conv2d, nn.Linear)) and not any(part in f"{name}." for part in UNCOUNTED_PARTS)
    )


def test_resnet34_backbone_as_imagenet_classifier_has_torchvision_parameter_count():
    classifier = GlobalPoolClassifier(ResNet34Backbone(3, stem_stride=4), num_classes=1000, pre_activation=False)
    assert parameter_count(classifier) == 21_797_672
    assert weighted_layers(classifier) == 34
    assert classifier(torch.zeros(1, 3, 64, 64)).shape == (1, 1000)


def test_densenet_blocks_as_densenet121_have_torchvision_parameter_count():
    backbone = DenseNetBackbone(3, (6, 12, 24, 16), growth_rate=32, stem_features=64, bn_size=4, compression=0.5)
    classifier = GlobalPoolClassifier(backbone, num_classes=1000, pre_activation=True)
    assert parameter_count(classifier) == 7_978_856
    assert weighted_layers(classifier) == 121
    assert backbone.out_channels == [256, 512, 1024, 1024]
    assert classifier(torch.zeros(1, 3, 64, 64)).shape == (1, 1000)


def test_feature_pyramid_has_torchvision_parameter_count():
    pyramid = FeaturePyramid([64, 128, 256, 512], 256)
    assert parameter_count(pyramid) == (64 + 128 + 256 + 512) * 256 + 4 * 256 + 4 * (256 * 256 * 9 + 256)
    levels = [torch.zeros(1, c, 16 // 2**i, 8 // 2**i) for i, c in enumerate([64, 128, 256, 512])]
    assert [tuple(level.shape) for level in pyramid(levels)] == [(1, 256, 16 >> i, 8 >> i) for i in range(4)]


def test_model_names_are_the_configs_names():
    assert MODEL_NAMES is configs.MODEL_NAMES
    assert set(EXPECTED_LAYERS) == set(MODEL_NAMES)


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_weighted_layer_count_is_the_named_depth(name):
    assert weighted_layers(build_model(name, in_channels=6, width_scale=0.25)) == EXPECTED_LAYERS[name]


@pytest.mark.parametrize("name", MODEL_NAMES)
@pytest.mark.parametrize("size", [(64, 32), (256, 64), (100, 37)], ids=["tiny", "demo", "odd"])
def test_logits_have_the_input_cells(name, size):
    model = build_model(name, in_channels=6, width_scale=0.25)
    logits = model(torch.randn(2, 6, *size, generator=torch.Generator().manual_seed(0)))
    assert logits.shape == (2, 1, *size)
    assert logits.dtype == torch.float32
    assert torch.isfinite(logits).all()


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_trains_from_scratch_and_gradient_reaches_the_first_conv(name):
    model = build_model(name, in_channels=4, width_scale=0.25)
    model.eval()
    model.train()
    assert all(parameter.requires_grad for parameter in model.parameters())
    norms = [module for module in model.modules() if isinstance(module, nn.BatchNorm2d)]
    assert norms and all(norm.training for norm in norms)
    logits = model(torch.randn(2, 4, 32, 16, generator=torch.Generator().manual_seed(0)))
    F.binary_cross_entropy_with_logits(logits, torch.ones_like(logits)).backward()
    first_conv = next(module for module in model.modules() if isinstance(module, nn.Conv2d))
    assert first_conv.in_channels == 4
    assert first_conv.weight.grad is not None
    assert torch.isfinite(first_conv.weight.grad).all() and first_conv.weight.grad.abs().sum() > 0


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_untrained_model_predicts_the_one_percent_prior(name):
    # In training mode, where the first steps run (BatchNorm on batch statistics).
    model = build_model(name, in_channels=3, width_scale=0.25).train()
    with torch.no_grad():
        probability = torch.sigmoid(model(torch.randn(2, 3, 32, 16, generator=torch.Generator().manual_seed(0))))
    assert 0.005 < probability.mean().item() < 0.02


def test_architecture_is_recorded():
    model = build_model("densenet-67", in_channels=12, width_scale=0.5)
    assert model.architecture == {"name": "densenet-67", "in_channels": 12, "width_scale": 0.5}
    assert parameter_count(model) == sum(p.numel() for p in model.parameters())


def test_unknown_model_names_the_choices():
    with pytest.raises(ZendarError, match="resnet50.*fpn-resnet34, densenet-37, densenet-67"):
        build_model("resnet50", in_channels=3)


@pytest.mark.parametrize("in_channels", [0, -3, 2.0, True, "3"])
def test_bad_in_channels_is_refused(in_channels):
    with pytest.raises(ZendarError, match="in_channels"):
        build_model("fpn-resnet34", in_channels=in_channels)


@pytest.mark.parametrize("width_scale", [0, -0.5, math.nan, math.inf, "1", False])
def test_bad_width_scale_is_refused(width_scale):
    with pytest.raises(ZendarError, match="width_scale"):
        build_model("densenet-37", in_channels=3, width_scale=width_scale)


def test_input_with_other_channels_is_refused():
    model = build_model("densenet-37", in_channels=6, width_scale=0.25)
    with pytest.raises(ZendarError, match=r"\[B, 6, R, D\].*\(2, 5, 32, 16\)"):
        model(torch.zeros(2, 5, 32, 16))


WINDOW = 3
RANGE_BINS = 32
DOPPLER_BINS = 16
BLOB_CELLS = 3


def moving_and_static_blobs(generator: torch.Generator, n: int) -> tuple[torch.Tensor, torch.Tensor]:
    """``n`` samples [n, WINDOW, R, D] of noise with two equally bright 3 x 3 blobs: one steps 4 range
    cells per time channel, one stays put. Labels [n, 1, R, D]: the moving blob in the last channel.

    In any one channel the blobs look alike; only the time axis tells them apart.
    """
    x = 0.1 * torch.randn(n, WINDOW, RANGE_BINS, DOPPLER_BINS, generator=generator)
    labels = torch.zeros(n, 1, RANGE_BINS, DOPPLER_BINS)
    step = BLOB_CELLS + 1
    last_moving_start = RANGE_BINS - BLOB_CELLS - (WINDOW - 1) * step
    for i in range(n):
        while True:
            range_start = int(torch.randint(0, last_moving_start + 1, (1,), generator=generator))
            doppler = int(torch.randint(0, DOPPLER_BINS - BLOB_CELLS + 1, (1,), generator=generator))
            static_range = int(torch.randint(0, RANGE_BINS - BLOB_CELLS + 1, (1,), generator=generator))
            static_doppler = int(torch.randint(0, DOPPLER_BINS - BLOB_CELLS + 1, (1,), generator=generator))
            if abs(doppler - static_doppler) > BLOB_CELLS:  # apart in Doppler, so they never overlap
                break
        for k in range(WINDOW):
            moving = range_start + k * step
            x[i, k, moving : moving + BLOB_CELLS, doppler : doppler + BLOB_CELLS] += 1.0
            x[i, k, static_range : static_range + BLOB_CELLS, static_doppler : static_doppler + BLOB_CELLS] += 1.0
        labels[i, 0, moving : moving + BLOB_CELLS, doppler : doppler + BLOB_CELLS] = 1.0
    return x, labels


def per_cell_f1(logits: torch.Tensor, labels: torch.Tensor) -> float:
    predicted = logits > 0
    truth = labels > 0.5
    tp = (predicted & truth).sum().item()
    fp = (predicted & ~truth).sum().item()
    fn = (~predicted & truth).sum().item()
    return 2 * tp / (2 * tp + fp + fn)


@pytest.mark.slow
@pytest.mark.parametrize("name", MODEL_NAMES)
def test_learns_to_tell_a_moving_blob_from_a_static_one(name):
    # A model blind to time can do little better than mark both blobs: precision 0.5, F1 0.67 < 0.8
    # (fed the last channel three times, densenet-37 reaches 0.58).
    torch.manual_seed(0)
    model = build_model(name, in_channels=WINDOW, width_scale=0.25)
    optimizer = torch.optim.Adam(model.parameters(), lr=3e-3)
    generator = torch.Generator().manual_seed(1)
    model.train()
    for _ in range(100):
        x, labels = moving_and_static_blobs(generator, 8)
        loss = F.binary_cross_entropy_with_logits(model(x), labels)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
    model.eval()
    x, labels = moving_and_static_blobs(torch.Generator().manual_seed(2), 64)
    with torch.no_grad():
        assert per_cell_f1(model(x), labels) > 0.8
