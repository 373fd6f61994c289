"""CNN inputs (paper §4.2): the K latest range-Doppler maps of every antenna, stacked over time.

``log_power_maps`` turns complex cubes ``[N, R, D, A]`` into normalised log-power maps
``[N, A, R, D]``; ``stack_window`` stacks K consecutive maps into ``[N - K + 1, K * A, R, D]``;
``MaskFrames`` pairs each window with the mask of its newest frame for training, building windows on
the fly from (possibly memory-mapped) maps so the paper-sized config never holds K copies in memory.

Channel layout of a window (everywhere): channel ``t * A + a`` is antenna ``a`` of the ``t``-th map of
the window, oldest first, newest last.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch.utils.data import Dataset

from zendar_dataset.errors import ZendarError

from zendar_baselines.mask_classes import BACKGROUND, MASK_DTYPE, MOVING, UNCERTAIN

POWER_FLOOR = 1e-30
"""Added to |x|² before the logarithm: below any thermal noise power of the simulator (~1e-11) and
the recorded data, it only keeps cells that are exactly zero (padding, a dead channel) finite."""

DB_SCALE = 10.0
"""Divisor of the median-referenced map in dB: a target 40 dB above the noise floor becomes 4.0."""

_CHUNK_FRAMES = 32


def log_power_maps(cubes: Any, *, out: np.ndarray | None = None) -> np.ndarray:
    """Normalised log-power range-Doppler maps of complex radar cubes.

    Each map (one frame, one antenna) is ``10 log10(|x|² + POWER_FLOOR)`` minus its own median,
    divided by ``DB_SCALE`` (10 dB). Why the median and a fixed scale: most range-Doppler cells hold
    only noise, so the median is the noise floor, unmoved by the few bright targets; subtracting it
    removes gain differences between radars, antennas and scenes. Dividing by a fixed 10 dB instead
    of each map's spread keeps a target's value equal to its SNR (in tens of dB) in every frame: a
    per-map standard deviation would shrink the same car in a frame full of bright clutter.

    Parameters
    ----------
    cubes : array-like, complex, shape [N, R, D, A]
        Range-Doppler-antenna cubes (``scene.array("radar/<name>/cube")`` or an ndarray); read
        ``_CHUNK_FRAMES`` frames at a time, so a lazy store is never loaded whole.
    out : ndarray, float32, shape [N, A, R, D], optional
        Where to write (e.g. ``np.lib.format.open_memmap`` for a scene too large for memory).

    Returns
    -------
    ndarray, float32, shape [N, A, R, D]
        Dimensionless: 0 at the map's median power, +1 per 10 dB above it.

    Raises
    ------
    ZendarError
        When ``cubes`` is not 4-D or not complex, or ``out`` has another shape or dtype.
    """
    shape = tuple(getattr(cubes, "shape", ()))
    if len(shape) != 4:
        raise ZendarError(f"log_power_maps: expected cubes of shape [N, R, D, A], found shape {shape}")
    dtype = np.dtype(getattr(cubes, "dtype", np.float32))
    if dtype.kind != "c":
        raise ZendarError(f"log_power_maps: expected complex cubes, found dtype {dtype}")
    n_frames, n_range, n_doppler, n_antennas = shape
    expected = (n_frames, n_antennas, n_range, n_doppler)
    if out is None:
        out = np.empty(expected, dtype=np.float32)
    elif out.shape != expected or out.dtype != np.float32:
        raise ZendarError(f"log_power_maps: out must be float32 of shape {expected}, found {out.dtype} {out.shape}")
    for start in range(0, n_frames, _CHUNK_FRAMES):
        chunk = np.asarray(cubes[start : start + _CHUNK_FRAMES])
        power = chunk.real.astype(np.float32) ** 2 + chunk.imag.astype(np.float32) ** 2
        power_db = 10.0 * np.log10(power + np.float32(POWER_FLOOR), dtype=np.float32)
        power_db = np.moveaxis(power_db, 3, 1)  # [n, A, R, D]
        median_db = np.median(power_db, axis=(2, 3), keepdims=True)
        out[start : start + len(chunk)] = (power_db - median_db) / np.float32(DB_SCALE)
    return out


def window_at(maps: np.ndarray, index: int, k: int) -> np.ndarray:
    """The input of window ``index``: maps ``index .. index + k - 1`` as ``[k * A, R, D]`` float32.

    Parameters
    ----------
    maps : ndarray, float32, shape [N, A, R, D]
    index : int
        First (oldest) map of the window; ``0 <= index <= N - k``.
    k : int
        Maps per window.
    """
    window = np.asarray(maps[index : index + k], dtype=np.float32)
    return window.reshape(k * maps.shape[1], maps.shape[2], maps.shape[3])


def _check_window(maps: Any, k: int, what: str) -> None:
    if getattr(maps, "ndim", None) != 4:
        raise ZendarError(f"{what}: expected maps of shape [N, A, R, D], found shape {tuple(getattr(maps, 'shape', ()))}")
    if not isinstance(k, (int, np.integer)) or k < 1:
        raise ZendarError(f"{what}: window k must be a positive integer, found {k!r}")
    if k > maps.shape[0]:
        raise ZendarError(f"{what}: window k={k} is longer than the {maps.shape[0]} maps given")


def stack_window(maps: np.ndarray, k: int) -> np.ndarray:
    """Stack every ``k`` consecutive maps over time: row ``i`` holds maps ``i .. i + k - 1``, newest last.

    Parameters
    ----------
    maps : ndarray, float32, shape [N, A, R, D]
    k : int
        Maps per window (``BenchConfig.window``).

    Returns
    -------
    ndarray, float32, shape [N - k + 1, k * A, R, D]
        Channel ``t * A + a`` of row ``i`` is antenna ``a`` of map ``i + t``.

    Raises
    ------
    ZendarError
        When ``maps`` is not 4-D or ``k`` is not in ``1 .. N``.
    """
    _check_window(maps, k, "stack_window")
    n_maps, n_antennas, n_range, n_doppler = maps.shape
    stacked = np.empty((n_maps - k + 1, k * n_antennas, n_range, n_doppler), dtype=np.float32)
    for index in range(len(stacked)):
        stacked[index] = window_at(maps, index, k)
    return stacked


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
        K, maps per sample. Sample ``i`` is ``(window_at(inputs, i, K), targets[i + K - 1])``;
        there are ``N - K + 1`` samples. Windows never cross the arrays given, so build one
        ``MaskFrames`` per scene and radar and join them with ``torch.utils.data.ConcatDataset``.

    Raises
    ------
    ZendarError
        When shapes disagree, the window is too long, or the targets are not uint8.
    """

    def __init__(self, inputs: np.ndarray | str | os.PathLike, targets: np.ndarray | str | os.PathLike, window: int = 1) -> None:
        self.inputs = _as_array(inputs, "inputs")
        self.targets = _as_array(targets, "targets")
        _check_window(self.inputs, window, "MaskFrames")
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
        return self.inputs.shape[0] - self.window + 1

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
        index = index % len(self)
        target = np.array(self.targets[index + self.window - 1], dtype=MASK_DTYPE)
        if target.max(initial=0) > UNCERTAIN:
            raise ZendarError(
                f"MaskFrames: mask of frame {index + self.window - 1} holds {int(target.max())}; "
                "expected 0 background, 1 moving, 2 uncertain"
            )
        return torch.from_numpy(window_at(self.inputs, index, self.window).copy()), torch.from_numpy(target)

    def class_counts(self) -> tuple[int, int]:
        """``(background cells, moving cells)`` over the masks of all samples (uncertain cells left out)."""
        background = moving = 0
        for start in range(self.window - 1, self.targets.shape[0], 256):
            block = np.asarray(self.targets[start : start + 256])
            background += int(np.count_nonzero(block == BACKGROUND))
            moving += int(np.count_nonzero(block == MOVING))
        return background, moving


__all__ = [
    "DB_SCALE",
    "POWER_FLOOR",
    "MaskFrames",
    "log_power_maps",
    "stack_window",
    "window_at",
]
