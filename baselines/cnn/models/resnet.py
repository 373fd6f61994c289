"""ResNet-34 backbone (He et al. 2016): a stem and four stages of [3, 4, 6, 3] BasicBlocks, in plain
torch (the package docstring says why not torchvision)."""

from __future__ import annotations

import torch
from torch import nn

from zendar_baselines.cnn.models.common import scaled_width
from zendar_dataset.errors import ZendarError

RESNET34_BLOCKS = (3, 4, 6, 3)
RESNET_STAGE_WIDTHS = (64, 128, 256, 512)


def stem(in_channels: int, out_channels: int, stride: int) -> nn.Sequential:
    """7x7 convolution, BN, ReLU, and for ``stride`` 4 the 3x3 max pool of the ImageNet networks.

    ``stride`` is the stem's total down-sampling: 1 (no stride), 2 (strided convolution) or 4
    (strided convolution and max pool, as in He et al. and Huang et al.).
    """
    if stride not in (1, 2, 4):
        raise ZendarError(f"stem stride must be 1, 2 or 4, got {stride!r}")
    layers: list[nn.Module] = [
        nn.Conv2d(in_channels, out_channels, kernel_size=7, stride=min(stride, 2), padding=3, bias=False),
        nn.BatchNorm2d(out_channels),
        nn.ReLU(inplace=True),
    ]
    if stride == 4:
        layers.append(nn.MaxPool2d(kernel_size=3, stride=2, padding=1))
    return nn.Sequential(*layers)


class BasicBlock(nn.Module):
    """Two 3x3 conv-BN layers and an identity (or strided 1x1 conv-BN projection) shortcut, then ReLU."""

    def __init__(self, in_channels: int, out_channels: int, stride: int) -> None:
        super().__init__()
        self.conv1 = nn.Conv2d(in_channels, out_channels, kernel_size=3, stride=stride, padding=1, bias=False)
        self.bn1 = nn.BatchNorm2d(out_channels)
        self.conv2 = nn.Conv2d(out_channels, out_channels, kernel_size=3, padding=1, bias=False)
        self.bn2 = nn.BatchNorm2d(out_channels)
        self.relu = nn.ReLU(inplace=True)
        if stride != 1 or in_channels != out_channels:
            self.downsample: nn.Module = nn.Sequential(
                nn.Conv2d(in_channels, out_channels, kernel_size=1, stride=stride, bias=False),
                nn.BatchNorm2d(out_channels),
            )
        else:
            self.downsample = nn.Identity()

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        out = self.relu(self.bn1(self.conv1(x)))
        out = self.bn2(self.conv2(out))
        return self.relu(out + self.downsample(x))


class ResNet34Backbone(nn.Module):
    """ResNet-34 without its classifier: returns the outputs of the four stages.

    Parameters
    ----------
    in_channels : int
        Input channels (3 for images; K stacked range-Doppler maps x antennas for the detector).
    width_scale : float
        Multiplies the stage widths 64 / 128 / 256 / 512.
    stem_stride : int
        Down-sampling of the stem: 4 as published, 2 for the detector (see ``FpnResNet34``).

    Attributes
    ----------
    out_channels : list of int
        Channels of the four stage outputs.
    strides : list of int
        Down-sampling of the four stage outputs relative to the input.
    """

    def __init__(self, in_channels: int, width_scale: float = 1.0, stem_stride: int = 4) -> None:
        super().__init__()
        widths = [scaled_width(width, width_scale) for width in RESNET_STAGE_WIDTHS]
        self.stem = stem(in_channels, widths[0], stem_stride)
        stages = []
        previous = widths[0]
        for index, (width, blocks) in enumerate(zip(widths, RESNET34_BLOCKS)):
            first_stride = 1 if index == 0 else 2
            stage = [BasicBlock(previous, width, first_stride)]
            stage += [BasicBlock(width, width, 1) for _ in range(blocks - 1)]
            stages.append(nn.Sequential(*stage))
            previous = width
        self.stages = nn.ModuleList(stages)
        self.out_channels = widths
        self.strides = [stem_stride * 2**index for index in range(len(RESNET34_BLOCKS))]

    def forward(self, x: torch.Tensor) -> list[torch.Tensor]:
        """``x`` [B, C, H, W] -> four maps [B, out_channels[i], H / strides[i], W / strides[i]]."""
        features = []
        out = self.stem(x)
        for stage in self.stages:
            out = stage(out)
            features.append(out)
        return features
