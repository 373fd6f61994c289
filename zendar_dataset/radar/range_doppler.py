"""Range-Doppler compression of raw FMCW frames.

Raw frames are ``[..., n_chirps, n_samples, A]`` complex baseband (the layout of
:func:`zendar_dataset.radar.fmcw.beat_signal_exact`); range-Doppler cubes are
``[..., R, D, A]`` with zero radial velocity at Doppler bin ``D // 2``.

Both transforms are the plain (unnormalised) forward DFT of the windowed data,
so a tone of amplitude ``a`` centred on a bin peaks at ``a * sum(w_range) * sum(w_doppler)``
and white noise of power ``s2`` per sample has power ``s2 * sum(w_range**2) * sum(w_doppler**2)``
per cell. numpy input goes through ``scipy.fft``; a torch tensor goes through
``torch.fft`` on its own device and comes back as a tensor.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any

import numpy as np
import scipy.fft
import scipy.signal

WindowSpec = str | None | np.ndarray


@lru_cache(maxsize=64)
def _named_window(name: str, n: int) -> np.ndarray:
    if name in ("rect", "rectangular", "boxcar", "none"):
        return np.ones(n)
    try:
        # DFT-even ("periodic") windows: the usual choice for spectral analysis.
        window = scipy.signal.get_window(name, n, fftbins=True)
    except ValueError as err:
        raise ValueError(f"unknown window {name!r}: {err}") from None
    window.flags.writeable = False
    return window


def window_values(window: WindowSpec, n: int) -> np.ndarray:
    """Window weights ``[n]`` float64 for a name accepted by ``scipy.signal.get_window``.

    ``None`` or ``"rect"`` give ones; an array is checked for length ``n`` and returned.
    """
    if window is None:
        return _named_window("rect", n)
    if isinstance(window, str):
        return _named_window(window.lower(), n)
    values = np.asarray(window, dtype=np.float64)
    if values.shape != (n,):
        raise ValueError(f"window array must have shape ({n},), got {values.shape}")
    return values


def window_enbw_bins(window: WindowSpec, n: int) -> float:
    """Equivalent noise bandwidth of a window in DFT bins, ``n * sum(w**2) / sum(w)**2``."""
    w = window_values(window, n)
    return float(n * np.sum(w * w) / np.sum(w) ** 2)


def _is_torch(x: Any) -> bool:
    return type(x).__module__.startswith("torch")


def _check_raw(raw: Any, name: str = "raw") -> None:
    if raw.ndim < 3:
        raise ValueError(f"{name} must be [..., n_chirps, n_samples, A], got shape {tuple(raw.shape)}")


def _range_fft_size(n_samples: int, n_range_bins: int | None) -> tuple[int, int]:
    """(FFT length, bins kept): zero-pad up to ``n_range_bins``, or keep the first ``n_range_bins`` bins."""
    if n_range_bins is None:
        return n_samples, n_samples
    if int(n_range_bins) < 1:
        raise ValueError(f"n_range_bins must be >= 1, got {n_range_bins}")
    n_range_bins = int(n_range_bins)
    return max(n_samples, n_range_bins), n_range_bins


@lru_cache(maxsize=32)
def _frame_window(range_window: Any, doppler_window: Any, n_chirps: int, n_samples: int, single: bool) -> np.ndarray:
    w_r = window_values(range_window, n_samples)
    w_d = window_values(doppler_window, n_chirps).copy()
    if n_chirps % 2 == 0:
        # (-1)^m before the DFT shifts its output by D/2: the fftshift comes for free.
        w_d[1::2] *= -1.0
    win = (w_d[:, None] * w_r[None, :])[:, :, None]
    win = win.astype(np.float32 if single else np.float64)
    win.flags.writeable = False
    return win


def _hashable_window(window: WindowSpec) -> Any:
    if window is None or isinstance(window, str):
        return window
    return tuple(np.asarray(window, dtype=np.float64).ravel().tolist())


def _as_window_spec(key: Any) -> WindowSpec:
    return np.asarray(key) if isinstance(key, tuple) else key


def range_doppler(
    raw: Any,
    *,
    range_window: WindowSpec = "hann",
    doppler_window: WindowSpec = "hann",
    n_range_bins: int | None = None,
    workers: int | None = -1,
) -> Any:
    """Range-Doppler compress raw frames.

    Parameters
    ----------
    raw : numpy.ndarray or torch.Tensor
        ``[..., n_chirps, n_samples, A]`` complex baseband samples (real input is
        promoted to complex64).
    range_window, doppler_window : str, None or array
        Window over fast time / slow time: a ``scipy.signal.get_window`` name
        (DFT-even), ``None``/``"rect"``, or explicit weights.
    n_range_bins : int, optional
        ``R``; larger than ``n_samples`` zero-pads the range FFT (range bins then
        shrink by ``n_samples / R``), smaller keeps only the first ``R`` bins
        of the ``n_samples``-point FFT (e.g. to drop the far half).
    workers : int, optional
        Threads for ``scipy.fft`` (``-1``: all cores); ignored for torch input.

    Returns
    -------
    numpy.ndarray or torch.Tensor
        ``[..., R, D, A]`` complex (complex64 for complex64/real input, else
        complex128 for numpy), Doppler bin ``D // 2`` at zero radial velocity,
        range bin ``r`` at ``r * range_bin_m`` (see :func:`range_axis_m`). The
        numpy result is a transposed view of a ``[..., D, R, A]`` buffer.
    """
    _check_raw(raw)
    n_chirps, n_samples = int(raw.shape[-3]), int(raw.shape[-2])
    n_fft, n_keep = _range_fft_size(n_samples, n_range_bins)
    if _is_torch(raw):
        return _range_doppler_torch(raw, range_window, doppler_window, n_fft, n_keep)
    x = np.asarray(raw)
    if not np.iscomplexobj(x):
        x = x.astype(np.complex64)
    single = x.dtype == np.complex64
    win = _frame_window(_hashable_window(range_window), _hashable_window(doppler_window), n_chirps, n_samples, single)
    buf = np.multiply(x, win, dtype=x.dtype)
    if n_fft == n_samples:
        spec = scipy.fft.fftn(buf, axes=(-3, -2), overwrite_x=True, workers=workers)
    else:
        spec = scipy.fft.fftn(buf, s=(n_chirps, n_fft), axes=(-3, -2), overwrite_x=True, workers=workers)
    if n_chirps % 2:
        spec = scipy.fft.fftshift(spec, axes=-3)
    if n_keep < n_fft:
        spec = spec[..., :n_keep, :]
    return np.swapaxes(spec, -3, -2)


def _torch_window(win_np: np.ndarray, like: Any) -> Any:
    import torch

    real_dtype = torch.float32 if like.dtype in (torch.complex64, torch.float32, torch.float16, torch.int16) else torch.float64
    return torch.tensor(np.array(win_np), dtype=real_dtype, device=like.device)


def _range_doppler_torch(raw: Any, range_window: WindowSpec, doppler_window: WindowSpec, n_fft: int, n_keep: int) -> Any:
    import torch

    x = raw if raw.is_complex() else raw.to(torch.complex64)
    n_chirps, n_samples = int(x.shape[-3]), int(x.shape[-2])
    win = _frame_window(
        _hashable_window(range_window), _hashable_window(doppler_window), n_chirps, n_samples, x.dtype == torch.complex64
    )
    spec = torch.fft.fftn(x * _torch_window(win, x), s=(n_chirps, n_fft), dim=(-3, -2))
    if n_chirps % 2:
        spec = torch.fft.fftshift(spec, dim=-3)
    if n_keep < n_fft:
        spec = spec[..., :n_keep, :]
    return spec.transpose(-3, -2)


def range_profiles(raw: Any, *, range_window: WindowSpec = "hann", n_range_bins: int | None = None, workers: int | None = -1) -> Any:
    """Per-chirp range compression (no Doppler processing).

    Parameters
    ----------
    raw : numpy.ndarray or torch.Tensor
        ``[..., n_chirps, n_samples, A]`` complex baseband samples.
    range_window : str, None or array
        Fast-time window (see :func:`range_doppler`).
    n_range_bins : int, optional
        As in :func:`range_doppler` (zero-padding upsamples the profile).
    workers : int, optional
        Threads for ``scipy.fft``.

    Returns
    -------
    numpy.ndarray or torch.Tensor
        ``[..., n_chirps, R, A]`` complex, the unnormalised forward DFT over fast
        time of the windowed samples. A scatterer at range ``R0`` peaks at bin
        ``R0 / range_bin_m`` with phase ``2*pi*(f_c*tau - S*tau**2/2)`` plus the
        DFT's linear phase of a tone between bins.
    """
    _check_raw(raw)
    n_samples = int(raw.shape[-2])
    n_fft, n_keep = _range_fft_size(n_samples, n_range_bins)
    w = window_values(range_window, n_samples)[:, None]
    if _is_torch(raw):
        import torch

        x = raw if raw.is_complex() else raw.to(torch.complex64)
        spec = torch.fft.fft(x * _torch_window(w, x), n=n_fft, dim=-2)
        return spec[..., :n_keep, :] if n_keep < n_fft else spec
    x = np.asarray(raw)
    if not np.iscomplexobj(x):
        x = x.astype(np.complex64)
    buf = np.multiply(x, w.astype(np.float32 if x.dtype == np.complex64 else np.float64), dtype=x.dtype)
    spec = scipy.fft.fft(buf, n=n_fft, axis=-2, overwrite_x=True, workers=workers)
    return spec[..., :n_keep, :] if n_keep < n_fft else spec


def range_axis_m(n_bins: int, range_bin_m: float) -> np.ndarray:
    """Range of each range bin, ``r * range_bin_m`` (m), ``[n_bins]`` float64."""
    return np.arange(int(n_bins)) * float(range_bin_m)


def velocity_axis_mps(n_bins: int, doppler_bin_mps: float) -> np.ndarray:
    """Radial velocity of each Doppler bin, ``(d - n_bins // 2) * doppler_bin_mps`` (m/s, > 0: receding), ``[n_bins]``."""
    return (np.arange(int(n_bins)) - int(n_bins) // 2) * float(doppler_bin_mps)
