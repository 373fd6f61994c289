"""CNN detectors of paper §4.2: per-cell dynamic-object masks from stacked range-Doppler maps.

Every model takes ``x`` float32 [B, C, R, D] (C = K stacked range-Doppler maps x antennas, log power,
normalised; R range bins, D Doppler bins, any sizes) and returns logits [B, 1, R, D]; sigmoid > 0.5
marks a moving cell. All are trained from scratch (plain BatchNorm, nothing frozen).

The building blocks (ResNet BasicBlock, the FPN top-down path, DenseNet-BC layers and transitions)
are written here in plain torch: the only Linux torchvision wheel matching this torch links against
the CUDA build of libtorch and fails to import beside the CPU build
("operator torchvision::nms does not exist").
"""

from __future__ import annotations

from torch import nn

from zendar_baselines.configs import MODEL_NAMES
from zendar_baselines.models.common import check_in_channels, check_width_scale
from zendar_baselines.models.densenet import DENSENET_BLOCK_LAYERS, ZoomOutDenseNet
from zendar_baselines.models.fpn import FpnResNet34
from zendar_dataset.errors import ZendarError

__all__ = ["MODEL_NAMES", "FpnResNet34", "ZoomOutDenseNet", "build_model", "parameter_count"]


def build_model(name: str, in_channels: int, width_scale: float = 1.0) -> nn.Module:
    """The detector called ``name``, freshly initialised.

    Parameters
    ----------
    name : str
        One of ``MODEL_NAMES``: ``fpn-resnet34``, ``densenet-37``, ``densenet-67``.
    in_channels : int
        C of the input [B, C, R, D].
    width_scale : float
        Multiplies every channel width (1.0 = the published widths).

    Returns
    -------
    nn.Module
        With ``architecture`` = {"name", "in_channels", "width_scale"}, what a checkpoint records to
        rebuild and check it.

    Raises
    ------
    ZendarError
        For an unknown name (naming the choices), a non-positive ``in_channels`` or ``width_scale``.
    """
    if name not in MODEL_NAMES:
        raise ZendarError(f"unknown model {name!r}: choose one of {', '.join(MODEL_NAMES)}")
    check_in_channels(in_channels)
    width_scale = check_width_scale(width_scale)
    if name == "fpn-resnet34":
        model: nn.Module = FpnResNet34(in_channels, width_scale)
    else:
        model = ZoomOutDenseNet(in_channels, DENSENET_BLOCK_LAYERS[name], growth_rate=32, width_scale=width_scale)
    model.architecture = {"name": name, "in_channels": in_channels, "width_scale": width_scale}
    return model


def parameter_count(model: nn.Module) -> int:
    """Number of trainable parameters (elements of the tensors that require grad)."""
    return sum(parameter.numel() for parameter in model.parameters() if parameter.requires_grad)
