"""FPN-ResNet-34 (Lin et al. 2017 on He et al. 2016): a feature pyramid over the ResNet-34 stages and a
head that fuses the pyramid at its finest level into one logit per range-Doppler cell, in plain torch
(the package docstring says why not torchvision)."""

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
from zendar_baselines.cnn.models.resnet import BasicBlock, ResNet34Backbone

FPN_CHANNELS = 256
HEAD_CHANNELS = 128
DETECTOR_STEM_STRIDE = 2


class FeaturePyramid(nn.Module):
    """The top-down path of Lin et al. 2017, without extra levels.

    Each input level gets a 1x1 lateral convolution to ``out_channels``; from the coarsest level
    down, the running map is upsampled (nearest, to the next level's size) and added to that
    level's lateral; each sum then goes through a 3x3 convolution. All convolutions have biases.

    Parameters
    ----------
    in_channels : list of int
        Channels of the input levels, finest first.
    out_channels : int
        Channels of every output level.
    """

    def __init__(self, in_channels: list[int], out_channels: int) -> None:
        super().__init__()
        self.lateral = nn.ModuleList(nn.Conv2d(channels, out_channels, kernel_size=1) for channels in in_channels)
        self.output = nn.ModuleList(
            nn.Conv2d(out_channels, out_channels, kernel_size=3, padding=1) for _ in in_channels
        )

    def forward(self, features: list[torch.Tensor]) -> list[torch.Tensor]:
        """Levels [B, in_channels[i], H_i, W_i], finest first -> [B, out_channels, H_i, W_i] each."""
        running = self.lateral[-1](features[-1])
        pyramid = [self.output[-1](running)]
        for level in range(len(features) - 2, -1, -1):
            lateral = self.lateral[level](features[level])
            running = lateral + F.interpolate(running, size=lateral.shape[-2:], mode="nearest")
            pyramid.insert(0, self.output[level](running))
        return pyramid


class FpnResNet34(nn.Module):
    """Per-cell dynamic-object logits from stacked range-Doppler maps: ResNet-34, FPN, fusion head.

    The stem down-samples by 2 rather than ResNet's 4: range-Doppler maps are small (64 x 32 in the
    tiny profile) and a moving car covers a few cells, so a stride-4 stem would merge neighbouring
    targets before the first block and leave a 2 x 1 map at the coarsest level. The pyramid levels
    are then at strides 2, 4, 8 and 16.

    The head brings each pyramid level through a 3x3 conv-BN-ReLU to 128 channels, upsamples it
    (bilinear) to the finest level, sums the levels, applies the 1x1 logit convolution and
    upsamples the logits (bilinear) to the input size. Weighted layers counted as in ResNet-34:
    the stem convolution, the 2 x 16 block convolutions and the logit convolution in place of the
    fully connected layer make 34; the shortcut projections, the pyramid's convolutions and the
    head's 3x3 convolutions are not counted, as in the published networks.

    Inputs whose sizes are not multiples of 16 are padded (edge replicated) and the logits cropped.

    Parameters
    ----------
    in_channels : int
        C, the stacked range-Doppler maps times antennas.
    width_scale : float
        Multiplies every channel width (stages 64..512, pyramid 256, head 128).
    """

    def __init__(self, in_channels: int, width_scale: float = 1.0) -> None:
        super().__init__()
        self.in_channels = check_in_channels(in_channels)
        width_scale = check_width_scale(width_scale)
        self.backbone = ResNet34Backbone(in_channels, width_scale, stem_stride=DETECTOR_STEM_STRIDE)
        pyramid_channels = scaled_width(FPN_CHANNELS, width_scale)
        head_channels = scaled_width(HEAD_CHANNELS, width_scale)
        self.fpn = FeaturePyramid(self.backbone.out_channels, pyramid_channels)
        self.head = nn.ModuleList(
            nn.Sequential(
                nn.Conv2d(pyramid_channels, head_channels, kernel_size=3, padding=1, bias=False),
                nn.BatchNorm2d(head_channels),
                nn.ReLU(inplace=True),
            )
            for _ in self.backbone.out_channels
        )
        self.logit = logit_conv(head_channels)
        self.size_multiple = self.backbone.strides[-1]
        init_from_scratch(self.backbone)
        init_from_scratch(self.fpn)
        init_from_scratch(self.head)
        # Each residual branch starts as zero, so the untrained network is a chain of identities
        # that trains stably from scratch (Goyal et al. 2017).
        for block in self.backbone.modules():
            if isinstance(block, BasicBlock):
                nn.init.zeros_(block.bn2.weight)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``x`` float32 [B, C, R, D] -> logits [B, 1, R, D] (sigmoid > 0.5: moving)."""
        check_input(x, self.in_channels)
        size = x.shape[-2:]
        padded = pad_to_multiple(x, self.size_multiple)
        pyramid = self.fpn(self.backbone(padded))
        finest = pyramid[0].shape[-2:]
        fused = self.head[0](pyramid[0])
        for level, head in zip(pyramid[1:], self.head[1:]):
            fused = fused + F.interpolate(head(level), size=finest, mode="bilinear", align_corners=False)
        logits = F.interpolate(self.logit(fused), size=padded.shape[-2:], mode="bilinear", align_corners=False)
        return logits[..., : size[0], : size[1]]
