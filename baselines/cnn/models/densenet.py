"""Zoom-out DenseNet (Huang et al. 2017 DenseNet-BC; zoom-out features of Mostajabi et al. 2015; paper
Figure 3), in plain torch (the package docstring says why not torchvision).

Layer counts follow DenseNet-121's: the stem convolution, two convolutions per bottleneck layer, one
per transition and one for the classifier; 121 = 1 + 2 (6 + 12 + 24 + 16) + 3 + 1. The paper names a
37-layer network with two dense blocks and a 67-layer one with four, without the split:

- densenet-37: 37 = 1 + 2 L + 1 + 1, so L = 17 bottleneck layers over 2 blocks;
- densenet-67: 67 = 1 + 2 L + 3 + 1, so L = 31 over 4 blocks.

The split keeps DenseNet-121's proportions 6 : 12 : 24 : 16 (the first two of them for two blocks),
scaled to L and rounded by largest remainder: 17 x (6, 12) / 18 = (5.67, 11.33) -> (6, 11);
31 x (6, 12, 24, 16) / 58 = (3.21, 6.41, 12.83, 8.55) -> (3, 6, 13, 9).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from zendar_baselines.cnn.models.common import (
    check_in_channels,
    check_input,
    check_width_scale,
    init_from_scratch,
    logit_conv,
    pad_to_multiple,
    scaled_width,
)
from zendar_baselines.cnn.models.resnet import stem
from zendar_dataset.errors import ZendarError

DENSENET_BLOCK_LAYERS: dict[str, tuple[int, ...]] = {
    "densenet-37": (6, 11),
    "densenet-67": (3, 6, 13, 9),
}
ZOOM_CHANNELS = 64
DETECTOR_STEM_STRIDE = 2


class DenseLayer(nn.Module):
    """DenseNet-BC bottleneck layer: BN-ReLU-1x1 conv (bn_size x growth) - BN-ReLU-3x3 conv (growth).

    Returns its input with the ``growth_rate`` new channels appended.
    """

    def __init__(self, in_channels: int, growth_rate: int, bn_size: int) -> None:
        super().__init__()
        bottleneck = bn_size * growth_rate
        self.layers = nn.Sequential(
            nn.BatchNorm2d(in_channels),
            nn.ReLU(inplace=True),
            nn.Conv2d(in_channels, bottleneck, kernel_size=1, bias=False),
            nn.BatchNorm2d(bottleneck),
            nn.ReLU(inplace=True),
            nn.Conv2d(bottleneck, growth_rate, kernel_size=3, padding=1, bias=False),
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.cat([x, self.layers(x)], dim=1)


def transition(in_channels: int, out_channels: int) -> nn.Sequential:
    """BN-ReLU-1x1 conv to ``out_channels``, then 2x2 average pooling."""
    return nn.Sequential(
        nn.BatchNorm2d(in_channels),
        nn.ReLU(inplace=True),
        nn.Conv2d(in_channels, out_channels, kernel_size=1, bias=False),
        nn.AvgPool2d(kernel_size=2, stride=2),
    )


class DenseNetBackbone(nn.Module):
    """DenseNet-BC without its classifier: returns the output of every dense block (not normalised).

    Parameters
    ----------
    in_channels : int
        Input channels.
    block_layers : tuple of int
        Bottleneck layers per dense block, e.g. (6, 12, 24, 16) for DenseNet-121.
    growth_rate : int
        Channels each bottleneck layer adds.
    stem_features : int
        Channels of the stem convolution.
    bn_size : int
        Bottleneck width as a multiple of ``growth_rate``.
    compression : float
        Share of channels a transition keeps (rounded down).
    stem_stride : int
        Down-sampling of the stem: 4 as published, 2 for the detector.

    Attributes
    ----------
    out_channels : list of int
        Channels of each block's output.
    strides : list of int
        Down-sampling of each block's output relative to the input.
    """

    def __init__(
        self,
        in_channels: int,
        block_layers: tuple[int, ...],
        growth_rate: int = 32,
        stem_features: int = 64,
        bn_size: int = 4,
        compression: float = 0.5,
        stem_stride: int = 4,
    ) -> None:
        super().__init__()
        if not block_layers or any(isinstance(n, bool) or not isinstance(n, int) or n < 1 for n in block_layers):
            raise ZendarError(f"block_layers must be a non-empty tuple of positive integers, got {block_layers!r}")
        self.stem = stem(in_channels, stem_features, stem_stride)
        self.blocks = nn.ModuleList()
        self.transitions = nn.ModuleList()
        self.out_channels: list[int] = []
        self.strides: list[int] = []
        channels = stem_features
        stride = stem_stride
        for index, layers in enumerate(block_layers):
            block = []
            for _ in range(layers):
                block.append(DenseLayer(channels, growth_rate, bn_size))
                channels += growth_rate
            self.blocks.append(nn.Sequential(*block))
            self.out_channels.append(channels)
            self.strides.append(stride)
            if index < len(block_layers) - 1:
                compressed = int(channels * compression)
                self.transitions.append(transition(channels, compressed))
                channels = compressed
                stride *= 2

    def forward(self, x: torch.Tensor) -> list[torch.Tensor]:
        """``x`` [B, C, H, W] -> one map per block [B, out_channels[i], H / strides[i], W / strides[i]]."""
        features = []
        out = self.stem(x)
        for index, block in enumerate(self.blocks):
            out = block(out)
            features.append(out)
            if index < len(self.transitions):
                out = self.transitions[index](out)
        return features


class ZoomOutDenseNet(nn.Module):
    """Per-cell dynamic-object logits from stacked range-Doppler maps: DenseNet-BC with zoom-out features.

    The output of every dense block goes through BN-ReLU-1x1 conv to 64 channels (at the block's
    own resolution, which keeps the full-resolution concatenation small), is upsampled (bilinear)
    to the input resolution and concatenated; BN-ReLU and a 1x1 convolution give the logit. These
    projections and the logit convolution are the zoom-out classifier and count as one layer (see
    the module docstring for the counts). The stem down-samples by 2 without max pooling, for the
    reason given in ``FpnResNet34``. Inputs are padded (edge replicated) to a multiple of the
    coarsest block's stride and the logits cropped.

    Parameters
    ----------
    in_channels : int
        C, the stacked range-Doppler maps times antennas.
    block_layers : tuple of int
        Bottleneck layers per dense block (``DENSENET_BLOCK_LAYERS`` holds the named ones).
    growth_rate : int
        Channels added per bottleneck layer before ``width_scale``; the stem has twice as many.
    width_scale : float
        Multiplies every channel width (growth rate, stem, zoom-out projections).
    """

    def __init__(
        self, in_channels: int, block_layers: tuple[int, ...], growth_rate: int = 32, width_scale: float = 1.0
    ) -> None:
        super().__init__()
        self.in_channels = check_in_channels(in_channels)
        width_scale = check_width_scale(width_scale)
        growth = scaled_width(growth_rate, width_scale)
        self.backbone = DenseNetBackbone(
            in_channels, tuple(block_layers), growth_rate=growth, stem_features=2 * growth,
            stem_stride=DETECTOR_STEM_STRIDE,
        )
        zoom_channels = scaled_width(ZOOM_CHANNELS, width_scale)
        self.zoom = nn.ModuleList(
            nn.Sequential(
                nn.BatchNorm2d(channels),
                nn.ReLU(inplace=True),
                nn.Conv2d(channels, zoom_channels, kernel_size=1, bias=False),
            )
            for channels in self.backbone.out_channels
        )
        fused_channels = zoom_channels * len(self.zoom)
        self.fuse = nn.Sequential(nn.BatchNorm2d(fused_channels), nn.ReLU(inplace=True))
        self.logit = logit_conv(fused_channels)
        self.size_multiple = self.backbone.strides[-1]
        init_from_scratch(self.backbone)
        init_from_scratch(self.zoom)
        init_from_scratch(self.fuse)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``x`` float32 [B, C, R, D] -> logits [B, 1, R, D] (sigmoid > 0.5: moving)."""
        check_input(x, self.in_channels)
        size = x.shape[-2:]
        padded = pad_to_multiple(x, self.size_multiple)
        zoomed = [
            F.interpolate(project(block), size=padded.shape[-2:], mode="bilinear", align_corners=False)
            for project, block in zip(self.zoom, self.backbone(padded))
        ]
        logits = self.logit(self.fuse(torch.cat(zoomed, dim=1)))
        return logits[..., : size[0], : size[1]]
