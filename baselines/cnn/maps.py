"""CNN inputs (paper §4.2): the K latest range-Doppler maps of every antenna, stacked over time.

``log_power_maps`` turns complex cubes ``[N, R, D, A]`` into normalised log-power maps
``[N, A, R, D]``; ``stack_window`` stacks, for every map, the K latest maps up to it into
``[N, K * A, R, D]`` (:class:`zendar_baselines.cnn.mask_frames.MaskFrames` pairs windows with masks
for training). A scene's first K - 1 maps have fewer predecessors: their windows repeat the scene's
first map in place of the missing ones, in training and at test time alike, so every cube of a
scene gets a prediction.

Channel layout of a window (everywhere): channel ``t * A + a`` is antenna ``a`` of the ``t``-th map of
the window, oldest first, newest last.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from zendar_dataset.errors import ZendarError

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


def window_at(maps: np.ndarray, newest: int, k: int) -> np.ndarray:
    """The input whose newest map is ``newest``: maps ``newest - k + 1 .. newest`` as ``[k * A, R, D]`` float32,
    map 0 standing in for those before the first.

    Parameters
    ----------
    maps : ndarray, float32, shape [N, A, R, D]
    newest : int
        Index of the window's newest map; ``0 <= newest < N``.
    k : int
        Maps per window.
    """
    indices = np.maximum(np.arange(newest - k + 1, newest + 1), 0)
    window = np.asarray(maps[indices[0] : newest + 1], dtype=np.float32)[indices - indices[0]]
    return window.reshape(k * maps.shape[1], maps.shape[2], maps.shape[3])


def check_window(maps: Any, k: int, what: str) -> None:
    """Raise ZendarError (prefixed with ``what``) unless ``maps`` is ``[N, A, R, D]`` with ``N >= 1`` and ``k >= 1``."""
    if getattr(maps, "ndim", None) != 4 or maps.shape[0] < 1:
        raise ZendarError(f"{what}: expected maps of shape [N, A, R, D] with N >= 1, found shape {tuple(getattr(maps, 'shape', ()))}")
    if not isinstance(k, (int, np.integer)) or k < 1:
        raise ZendarError(f"{what}: window k must be a positive integer, found {k!r}")


def stack_window(maps: np.ndarray, k: int) -> np.ndarray:
    """Stack, for every map, the ``k`` latest maps up to it: row ``i`` holds maps ``i - k + 1 .. i``, newest last.

    Maps before the first are the first map repeated (:func:`window_at`), so there is a row for
    every map, even in a scene shorter than ``k``.

    Parameters
    ----------
    maps : ndarray, float32, shape [N, A, R, D]
    k : int
        Maps per window (``BenchConfig.window``).

    Returns
    -------
    ndarray, float32, shape [N, k * A, R, D]
        Channel ``t * A + a`` of row ``i`` is antenna ``a`` of map ``max(i - k + 1 + t, 0)``.

    Raises
    ------
    ZendarError
        When ``maps`` is not 4-D with at least one map, or ``k`` is not a positive integer.
    """
    check_window(maps, k, "stack_window")
    n_maps, n_antennas, n_range, n_doppler = maps.shape
    stacked = np.empty((n_maps, k * n_antennas, n_range, n_doppler), dtype=np.float32)
    for index in range(n_maps):
        stacked[index] = window_at(maps, index, k)
    return stacked


__all__ = [
    "DB_SCALE",
    "POWER_FLOOR",
    "log_power_maps",
    "stack_window",
    "window_at",
]
