"""What the CNN detectors share: channel widths, initialisation, padding to the network's stride, the
per-cell logit layer, and a global-pool classifier that turns a backbone into its ImageNet form."""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from zendar_dataset.errors import ZendarError

POSITIVE_PRIOR = 0.01
"""Share of moving cells the untrained detector predicts: the logit bias starts at log(p / (1 - p))."""


def scaled_width(width: int, width_scale: float) -> int:
    """``width`` channels times ``width_scale``, rounded, at least one channel."""
    return max(1, round(width * width_scale))


def check_in_channels(in_channels: int) -> int:
    """``in_channels`` when it is a positive int; ZendarError otherwise."""
    if isinstance(in_channels, bool) or not isinstance(in_channels, int) or in_channels < 1:
        raise ZendarError(f"in_channels must be a positive integer, got {in_channels!r}")
    return in_channels


def check_width_scale(width_scale: float) -> float:
    """``width_scale`` as a float when it is finite and positive; ZendarError otherwise."""
    if isinstance(width_scale, bool) or not isinstance(width_scale, (int, float)):
        raise ZendarError(f"width_scale must be a positive number, got {width_scale!r}")
    if not math.isfinite(width_scale) or width_scale <= 0:
        raise ZendarError(f"width_scale must be a finite positive number, got {width_scale!r}")
    return float(width_scale)


def init_from_scratch(module: nn.Module) -> None:
    """Kaiming-normal convolutions (fan-out, ReLU gain), BatchNorm at identity, for training from scratch."""
    for layer in module.modules():
        if isinstance(layer, nn.Conv2d):
            nn.init.kaiming_normal_(layer.weight, mode="fan_out", nonlinearity="relu")
            if layer.bias is not None:
                nn.init.zeros_(layer.bias)
        elif isinstance(layer, nn.BatchNorm2d):
            nn.init.ones_(layer.weight)
            nn.init.zeros_(layer.bias)


def logit_conv(in_channels: int) -> nn.Conv2d:
    """The 1x1 convolution that gives one logit per cell.

    Its bias starts at the logit of a 1 % positive share and its weights near zero (Lin et al.
    2017, focal loss): moving cells are rare, and a detector that starts at p = 0.5 everywhere
    spends its first steps on a huge background loss that can destabilise training.
    """
    conv = nn.Conv2d(in_channels, 1, kernel_size=1)
    nn.init.normal_(conv.weight, std=0.01)
    nn.init.constant_(conv.bias, math.log(POSITIVE_PRIOR / (1 - POSITIVE_PRIOR)))
    return conv


def check_input(x: torch.Tensor, in_channels: int) -> None:
    """ZendarError unless ``x`` is a float ``[B, in_channels, R, D]`` tensor."""
    if x.ndim != 4 or x.shape[1] != in_channels or not x.is_floating_point():
        raise ZendarError(
            f"the detector expects a float tensor [B, {in_channels}, R, D] (stacked range-Doppler maps), "
            f"got {x.dtype} of shape {tuple(x.shape)}"
        )


def pad_to_multiple(x: torch.Tensor, multiple: int) -> torch.Tensor:
    """``x`` [B, C, R, D] padded at the high end of R and D, by replicating the edge, to multiples of
    ``multiple``, so that every level of the network halves the one above exactly."""
    pad_range = -x.shape[2] % multiple
    pad_doppler = -x.shape[3] % multiple
    if pad_range == 0 and pad_doppler == 0:
        return x
    return F.pad(x, (0, pad_doppler, 0, pad_range), mode="replicate")


class GlobalPoolClassifier(nn.Module):
    """An image classifier on a backbone's last feature map: [BN-ReLU], global average pool, linear.

    Not a detector: it is the ImageNet form of a backbone, whose parameter count can be checked
    against the published networks.

    Parameters
    ----------
    backbone : nn.Module
        Returns a list of feature maps from ``forward``; has ``out_channels`` (list of int).
    num_classes : int
        Outputs of the linear layer.
    pre_activation : bool
        BatchNorm and ReLU before pooling (DenseNet's last features are not normalised; ResNet's are).
    """

    def __init__(self, backbone: nn.Module, num_classes: int, pre_activation: bool) -> None:
        super().__init__()
        self.backbone = backbone
        features = backbone.out_channels[-1]
        self.norm = nn.Sequential(nn.BatchNorm2d(features), nn.ReLU(inplace=True)) if pre_activation else nn.Identity()
        self.fc = nn.Linear(features, num_classes)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``x`` [B, C, H, W] -> class logits [B, num_classes]."""
        last = self.norm(self.backbone(x)[-1])
        return self.fc(torch.flatten(F.adaptive_avg_pool2d(last, 1), 1))
