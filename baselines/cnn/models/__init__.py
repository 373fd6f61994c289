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

from collections.abc import Callable
from typing import TYPE_CHECKING

from zendar_dataset.errors import ZendarError

if TYPE_CHECKING:
    from torch import nn

__all__ = ["MODEL_BUILDERS", "MODEL_NAMES", "build_model", "densenet37", "densenet67", "fpn_resnet34", "parameter_count"]


# The builders import torch when called, so that naming a model (configs, command lines) stays light.
def fpn_resnet34(in_channels: int, width_scale: float = 1.0) -> nn.Module:
    """FPN on a ResNet-34 backbone (:class:`zendar_baselines.cnn.models.fpn.FpnResNet34`)."""
    from zendar_baselines.cnn.models.fpn import FpnResNet34

    return FpnResNet34(in_channels, width_scale)


def densenet37(in_channels: int, width_scale: float = 1.0) -> nn.Module:
    """Zoom-out DenseNet-37: dense blocks of 6 and 11 layers, growth rate 32."""
    from zendar_baselines.cnn.models.densenet import DENSENET_BLOCK_LAYERS, ZoomOutDenseNet

    return ZoomOutDenseNet(in_channels, DENSENET_BLOCK_LAYERS["densenet-37"], growth_rate=32, width_scale=width_scale)


def densenet67(in_channels: int, width_scale: float = 1.0) -> nn.Module:
    """Zoom-out DenseNet-67: dense blocks of 3, 6, 13 and 9 layers, growth rate 32."""
    from zendar_baselines.cnn.models.densenet import DENSENET_BLOCK_LAYERS, ZoomOutDenseNet

    return ZoomOutDenseNet(in_channels, DENSENET_BLOCK_LAYERS["densenet-67"], growth_rate=32, width_scale=width_scale)


#: The models' names and builders (as torchvision's registry): configs refer to these names.
MODEL_BUILDERS: dict[str, Callable[[int, float], nn.Module]] = {
    "fpn-resnet34": fpn_resnet34,
    "densenet-37": densenet37,
    "densenet-67": densenet67,
}
MODEL_NAMES = tuple(MODEL_BUILDERS)


def build_model(name: str, in_channels: int, width_scale: float = 1.0, inputs: dict[str, bool] | None = None) -> nn.Module:
    """The detector called ``name``, freshly initialised.

    Parameters
    ----------
    name : str
        One of ``MODEL_NAMES``: ``fpn-resnet34``, ``densenet-37``, ``densenet-67``.
    in_channels : int
        C of the input [B, C, R, D].
    width_scale : float
        Multiplies every channel width (1.0 = the published widths).
    inputs : dict, optional
        The optional input channels the model reads
        (:meth:`zendar_baselines.cnn.input_channels.InputChannels.to_json`); None for the paper's input.

    Returns
    -------
    nn.Module
        With ``architecture`` = {"name", "in_channels", "width_scale"} (and "inputs" when given), what
        a checkpoint records to rebuild and check it and to make its input.

    Raises
    ------
    ZendarError
        For an unknown name (naming the choices), a non-positive ``in_channels`` or ``width_scale``.
    """
    from zendar_baselines.cnn.models.common import check_in_channels, check_width_scale

    if name not in MODEL_BUILDERS:
        raise ZendarError(f"unknown model {name!r}: choose one of {', '.join(MODEL_NAMES)}")
    check_in_channels(in_channels)
    width_scale = check_width_scale(width_scale)
    model = MODEL_BUILDERS[name](in_channels, width_scale)
    model.architecture = {"name": name, "in_channels": in_channels, "width_scale": width_scale}
    if inputs is not None:
        model.architecture["inputs"] = dict(inputs)
    return model


def parameter_count(model: nn.Module) -> int:
    """Number of trainable parameters (elements of the tensors that require grad)."""
    return sum(parameter.numel() for parameter in model.parameters() if parameter.requires_grad)
