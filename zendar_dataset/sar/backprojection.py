"""Time-domain SAR backprojection onto an :class:`~zendar_dataset.sar.grid.ImageGrid`.

Two backends compute the same float32 sum: ``"torch"`` (CPU or CUDA, chunked
tensor code, :mod:`~zendar_dataset.sar.backprojection_torch`) and ``"numba"`` (a
parallel, vectorised CPU kernel, :mod:`~zendar_dataset.sar.backprojection_numba`,
far faster than torch on a CPU). Both reference every pixel's range to a row-segment
centre in float64 (see :mod:`zendar_dataset.sar.segments`) so float32 stays accurate
even for grids and antenna positions in ECEF. Each backend's library is imported on
first use, so ``import zendar_dataset.sar`` stays light.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from zendar_dataset.sar.aperture import AZIMUTH_WINDOWS, azimuth_weights
from zendar_dataset.sar.grid import ImageGrid

if TYPE_CHECKING:
    import torch

SPEED_OF_LIGHT_MPS = 299_792_458.0

BACKENDS = ("auto", "numba", "torch")


def backproject(
    range_profiles: np.ndarray | torch.Tensor,
    positions_m: np.ndarray | torch.Tensor,
    grid: ImageGrid,
    *,
    range_bin_m: float,
    center_frequency_hz: float,
    range_offset_m: float = 0.0,
    azimuth_window: str = "rectangular",
    backend: str = "auto",
    device: str | torch.device | None = None,
    torch_compile: bool = False,
) -> np.ndarray | torch.Tensor:
    """Form a complex SAR image by time-domain backprojection.

    ``image[i, j] = Σ_p w_p · interp(profile_p, R_pij) · exp(−j·4π·R_pij/λ)`` with
    ``R_pij = |x_ij − positions_m[p]|``, linear interpolation in range and zero
    outside the profile. It removes the phase ``exp(+j·4π·R/λ)`` that a
    range-compressed profile carries at range ``R`` (docs/architecture.md), so a
    point scatterer adds up in phase at its pixel. Coherent processing of several
    antennas or radars is the same call with their pulses concatenated.

    Parameters
    ----------
    range_profiles : numpy.ndarray or torch.Tensor, shape (P, R), complex64
        Range-compressed pulses; sample ``r`` of pulse ``p`` is at one-way range
        ``range_offset_m + r·range_bin_m`` from that pulse's phase centre. ``R ≥ 2``.
    positions_m : array_like, shape (P, 3), float64
        Phase centre of each pulse, in the grid's frame (ECEF, ENU or ego), metres.
    grid : ImageGrid
        Pixels to form.
    range_bin_m : float
        Range sample spacing, metres (> 0).
    center_frequency_hz : float
        Carrier frequency ``f``; ``λ = c / f``.
    range_offset_m : float
        Range of sample 0, metres.
    azimuth_window : {"rectangular", "hann"}
        Slow-time taper ``w_p``, evaluated at each pulse's position along the aperture
        (:func:`zendar_dataset.sar.aperture.azimuth_weights`): ``"hann"`` keeps a strong
        scatterer's sidelobes off its range circle, widening the cross-range response from
        0.886 to 1.441 · λR / (2L sin θ) (docs/sar.md).
    backend : {"auto", "numba", "torch"}
        ``"auto"`` picks ``"torch"`` when ``range_profiles`` is a tensor or
        ``device`` is given, else ``"numba"``.
    device : str or torch.device, optional
        Torch device (e.g. ``"cuda"``); default: the device of ``range_profiles``
        when it is a tensor, else the CPU.
    torch_compile : bool
        Torch backend: fuse the per-pixel work with ``torch.compile`` (one kernel
        instead of ~40 passes over memory; what a GPU needs to be fast). The first
        call compiles (tens of seconds; cached on disk by torch afterwards).

    Returns
    -------
    numpy.ndarray or torch.Tensor, shape grid.shape, complex64
        A tensor (on the torch device) when ``range_profiles`` is a tensor, else a
        numpy array.

    Notes
    -----
    Accuracy in float32: a range of 50 m carries ~1.6e5 rad of phase at 77 GHz, and
    float32 holds it to ~1e-2 rad only; ECEF coordinates (~6.4e6 m) would not even
    hold the position to a wavelength. Every image row is therefore cut into short
    segments; for each (segment, pulse) pair the segment centre's range ``R_ref``, the
    fractional cycles of ``2·R_ref/λ`` and the interpolation base index are computed
    in float64, and the per-pixel float32 code computes only ``R − R_ref`` (exactly,
    from ``R² = R_ref² + s``) and the phase of that difference. The phase error is
    then ~1e-4 rad wherever the scene is, including ECEF.
    """
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
    if azimuth_window not in AZIMUTH_WINDOWS:
        raise ValueError(f"azimuth_window must be one of {sorted(AZIMUTH_WINDOWS)}, got {azimuth_window!r}")
    if not isinstance(grid, ImageGrid):
        raise TypeError(f"grid must be an ImageGrid, got {type(grid).__name__}")
    # torch is imported only when a tensor or the torch backend asks for it.
    is_tensor = _is_tensor(range_profiles)
    if not is_tensor:
        range_profiles = np.asarray(range_profiles)
    if backend == "auto":
        backend = "torch" if is_tensor or device is not None else "numba"
    if backend == "numba" and device is not None and str(device) != "cpu":
        raise ValueError(f"the numba backend runs on the CPU, got device={device!r}")

    if _is_tensor(positions_m):
        positions_m = positions_m.detach().cpu().numpy()
    positions = np.asarray(positions_m, dtype=np.float64)
    _check_inputs(tuple(range_profiles.shape), positions, range_bin_m, center_frequency_hz, range_offset_m)
    cycles_per_m = 2.0 * center_frequency_hz / SPEED_OF_LIGHT_MPS
    weights = None if azimuth_window == "rectangular" else azimuth_weights(positions, azimuth_window)

    if backend == "numba":
        from zendar_dataset.sar.backprojection_numba import backproject_numba

        profiles = range_profiles.detach().cpu().numpy() if is_tensor else range_profiles
        if weights is not None:
            profiles = profiles * weights[:, None]
        image = backproject_numba(
            profiles.astype(np.complex64, copy=False), positions, grid, range_bin_m, range_offset_m, cycles_per_m
        )
        if is_tensor:
            import torch

            return torch.from_numpy(image)
        return image

    import torch

    from zendar_dataset.sar.backprojection_torch import backproject_torch

    if device is None:
        device = range_profiles.device if is_tensor else torch.device("cpu")
    profiles_t = torch.as_tensor(range_profiles, device=torch.device(device)).to(torch.complex64)
    if weights is not None:
        profiles_t = profiles_t * torch.as_tensor(weights, device=profiles_t.device)[:, None]
    image = backproject_torch(profiles_t, positions, grid, range_bin_m, range_offset_m, cycles_per_m, torch_compile)
    return image if is_tensor else image.cpu().numpy()


def _is_tensor(value: Any) -> bool:
    return type(value).__module__.startswith("torch")


def _check_inputs(
    profile_shape: tuple[int, ...],
    positions: np.ndarray,
    range_bin_m: float,
    center_frequency_hz: float,
    range_offset_m: float,
) -> None:
    problems = []
    if len(profile_shape) != 2 or profile_shape[1] < 2:
        problems.append(f"range_profiles must have shape (P, R) with R >= 2, got {profile_shape}")
    if positions.ndim != 2 or positions.shape[1:] != (3,):
        problems.append(f"positions_m must have shape (P, 3), got {positions.shape}")
    elif len(profile_shape) == 2 and positions.shape[0] != profile_shape[0]:
        problems.append(
            f"positions_m has {positions.shape[0]} pulses but range_profiles has {profile_shape[0]}"
        )
    elif not np.all(np.isfinite(positions)):
        problems.append("positions_m must be finite")
    if not (math.isfinite(range_bin_m) and range_bin_m > 0):
        problems.append(f"range_bin_m must be positive, got {range_bin_m!r}")
    if not (math.isfinite(center_frequency_hz) and center_frequency_hz > 0):
        problems.append(f"center_frequency_hz must be positive, got {center_frequency_hz!r}")
    if not math.isfinite(range_offset_m):
        problems.append(f"range_offset_m must be finite, got {range_offset_m!r}")
    if problems:
        raise ValueError("backproject: " + "; ".join(problems))
