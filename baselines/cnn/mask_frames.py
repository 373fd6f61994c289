"""Training samples of the CNNs: windows of range-Doppler maps paired with the mask of their newest frame.

Windows are built on the fly from (possibly memory-mapped) maps, so the paper-sized config never
holds K copies in memory. Channel layout as in :mod:`zendar_baselines.cnn.maps`.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import Dataset

from zendar_dataset.errors import ZendarError

from zendar_baselines.cnn.maps import check_window, window_at
from zendar_baselines.labels.mask_classes import BACKGROUND, MASK_DTYPE, MOVING, UNCERTAIN


def _as_array(source: np.ndarray | str | os.PathLike, what: str) -> np.ndarray:
    if isinstance(source, (str, os.PathLike)):
        try:
            return np.load(Path(source), mmap_mode="r")
        except (OSError, ValueError) as exc:
            raise ZendarError(f"MaskFrames: {what} {str(source)!r}: cannot read as .npy ({exc})") from None
    return source


class MaskFrames(Dataset):
    """Windows of range-Doppler maps paired with the dynamic-object mask of their newest frame.

    Parameters
    ----------
    inputs : ndarray or path to .npy, float32, shape [N, A, R, D]
        Maps of one radar of one scene (``log_power_maps``), or already stacked windows
        ``[N, C, R, D]`` with ``window=1``. A path, or an array from ``np.load(..., mmap_mode="r")``,
        is read one window at a time.
    targets : ndarray or path to .npy, uint8, shape [N, R, D]
        Mask of each map's frame: 0 background, 1 moving, 2 uncertain (ignored by the loss).
    window : int
        K, maps per sample. Sample ``i`` is ``(window_at(inputs, i, K), targets[i])``: the window
        ending at map ``i``, the first map repeated before the scene's start as at test time
        (:func:`zendar_baselines.cnn.maps.stack_window`); there are ``N`` samples. Windows never
        cross the arrays given, so build one ``MaskFrames`` per scene and radar and join them with
        ``torch.utils.data.ConcatDataset``.

    Raises
    ------
    ZendarError
        When shapes disagree, the window is not a positive integer, or the targets are not uint8.
    """

    def __init__(self, inputs: np.ndarray | str | os.PathLike, targets: np.ndarray | str | os.PathLike, window: int = 1) -> None:
        self.inputs = _as_array(inputs, "inputs")
        self.targets = _as_array(targets, "targets")
        check_window(self.inputs, window, "MaskFrames")
        if getattr(self.targets, "ndim", None) != 3:
            raise ZendarError(f"MaskFrames: expected targets of shape [N, R, D], found shape {tuple(getattr(self.targets, 'shape', ()))}")
        if self.targets.dtype != MASK_DTYPE:
            raise ZendarError(f"MaskFrames: expected uint8 targets (0 background, 1 moving, 2 uncertain), found {self.targets.dtype}")
        if self.targets.shape[0] != self.inputs.shape[0] or self.targets.shape[1:] != self.inputs.shape[2:]:
            raise ZendarError(
                f"MaskFrames: targets {tuple(self.targets.shape)} do not align with inputs {tuple(self.inputs.shape)} "
                "(expected [N, R, D] for inputs [N, C, R, D])"
            )
        self.window = int(window)

    @property
    def in_channels(self) -> int:
        """Channels of one sample, ``window * A``."""
        return self.window * self.inputs.shape[1]

    def __len__(self) -> int:
        return self.inputs.shape[0]

    def __getitem__(self, index: int) -> tuple[torch.Tensor, torch.Tensor]:
        """Sample ``index``: float32 ``[K * A, R, D]`` input and uint8 ``[R, D]`` mask of its newest frame.

        Raises
        ------
        ZendarError
            When the mask holds a value other than 0, 1 or 2 (checked per sample, so a memory-mapped
            mask is never read whole).
        """
        if not -len(self) <= index < len(self):
            raise IndexError(f"MaskFrames index {index} out of range for {len(self)} samples")
        return self._sample(index % len(self))

    def _sample(self, index: int) -> tuple[torch.Tensor, torch.Tensor]:
        """Sample ``index`` (``0 <= index < N``): the window ending at map ``index`` and that map's mask."""
        target = np.array(self.targets[index], dtype=MASK_DTYPE)
        if target.max(initial=0) > UNCERTAIN:
            raise ZendarError(
                f"MaskFrames: mask of frame {index} holds {int(target.max())}; "
                "expected 0 background, 1 moving, 2 uncertain"
            )
        return torch.from_numpy(window_at(self.inputs, index, self.window).copy()), torch.from_numpy(target)

    def class_counts(self) -> tuple[int, int]:
        """``(background cells, moving cells)`` over the masks of all samples (uncertain cells left out)."""
        background = moving = 0
        for start in range(0, self.targets.shape[0], 256):
            block = np.asarray(self.targets[start : start + 256])
            background += int(np.count_nonzero(block == BACKGROUND))
            moving += int(np.count_nonzero(block == MOVING))
        return background, moving


class MaskFrameSubset(MaskFrames):
    """Some of the samples of a :class:`MaskFrames`: those whose mask is a target to train on.

    Parameters
    ----------
    inputs, targets, window
        As :class:`MaskFrames`.
    samples : sequence of int
        Indices of the samples kept (``0 <= i < N``: sample ``i`` is the window ending at map ``i``), in
        the order they are served.

    Raises
    ------
    ZendarError
        As :class:`MaskFrames`, and for a sample index out of range.
    """

    def __init__(self, inputs: np.ndarray | str | os.PathLike, targets: np.ndarray | str | os.PathLike, window: int,
                 samples) -> None:
        super().__init__(inputs, targets, window)
        self.samples = np.asarray(samples, np.int64).reshape(-1)
        n_all = self.inputs.shape[0]
        if self.samples.size and (self.samples.min() < 0 or self.samples.max() >= n_all):
            raise ZendarError(f"MaskFrameSubset: sample indices must lie in [0, {n_all}), found {self.samples.min()} .. "
                              f"{self.samples.max()}")

    def __len__(self) -> int:
        return int(self.samples.size)

    def __getitem__(self, index: int) -> tuple[torch.Tensor, torch.Tensor]:
        """Kept sample ``index``: :meth:`MaskFrames.__getitem__` of ``samples[index]``."""
        if not -len(self) <= index < len(self):
            raise IndexError(f"MaskFrameSubset index {index} out of range for {len(self)} samples")
        return self._sample(int(self.samples[index]))

    def class_counts(self) -> tuple[int, int]:
        """``(background cells, moving cells)`` over the kept samples' masks (uncertain cells left out)."""
        background = moving = 0
        for start in range(0, self.samples.size, 256):
            block = np.asarray(self.targets[self.samples[start : start + 256]])
            background += int(np.count_nonzero(block == BACKGROUND))
            moving += int(np.count_nonzero(block == MOVING))
        return background, moving
