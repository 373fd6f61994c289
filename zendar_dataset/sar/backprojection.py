"""Time-domain SAR backprojection onto an :class:`~zendar_dataset.sar.grid.ImageGrid`.

Two backends compute the same float32 sum: ``"torch"`` (CPU or CUDA, chunked
tensor code) and ``"numba"`` (a parallel, vectorised CPU kernel, several times
faster than torch on a CPU). Both reference every pixel's range to a row-segment
centre in float64 (see :mod:`zendar_dataset.sar.segments`) so float32 stays accurate
even for grids and antenna positions in ECEF.
"""

from __future__ import annotations

import functools
import math
from typing import Any

import numpy as np
import torch

from zendar_dataset.sar.grid import ImageGrid
from zendar_dataset.sar.segments import segment_length_px

SPEED_OF_LIGHT_MPS = 299_792_458.0

# Elements of the [tiles, pulses, segment] float32 intermediates per torch chunk:
# large enough to amortise kernel launches on a GPU, small enough for CPU caches.
_TORCH_CHUNK_ELEMENTS = {"cpu": 1 << 20, "cuda": 1 << 26}

BACKENDS = ("auto", "numba", "torch")


def backproject(
    range_profiles: np.ndarray | torch.Tensor,
    positions_m: np.ndarray | torch.Tensor,
    grid: ImageGrid,
    *,
    range_bin_m: float,
    center_frequency_hz: float,
    range_offset_m: float = 0.0,
    backend: str = "auto",
    device: str | torch.device | None = None,
    torch_compile: bool = False,
) -> np.ndarray | torch.Tensor:
    """Form a complex SAR image by time-domain backprojection.

    ``image[i, j] = Σ_p interp(profile_p, R_pij) · exp(−j·4π·R_pij/λ)`` with
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
    if not isinstance(grid, ImageGrid):
        raise TypeError(f"grid must be an ImageGrid, got {type(grid).__name__}")
    is_tensor = isinstance(range_profiles, torch.Tensor)
    if backend == "auto":
        backend = "torch" if is_tensor or device is not None else "numba"
    if backend == "numba" and device is not None and torch.device(device).type != "cpu":
        raise ValueError(f"the numba backend runs on the CPU, got device={device!r}")

    profiles = _as_numpy(range_profiles) if backend == "numba" else None
    profile_shape = tuple(range_profiles.shape)
    positions = np.asarray(
        positions_m.detach().cpu().numpy() if isinstance(positions_m, torch.Tensor) else positions_m,
        dtype=np.float64,
    )
    _check_inputs(profile_shape, positions, range_bin_m, center_frequency_hz, range_offset_m)
    cycles_per_m = 2.0 * center_frequency_hz / SPEED_OF_LIGHT_MPS

    if backend == "numba":
        from zendar_dataset.sar.backprojection_numba import backproject_numba

        image = backproject_numba(
            profiles, positions, grid, range_bin_m, range_offset_m, cycles_per_m
        )
        return torch.from_numpy(image) if is_tensor else image

    if device is None:
        device = range_profiles.device if is_tensor else torch.device("cpu")
    device = torch.device(device)
    profiles_t = torch.as_tensor(range_profiles, device=device).to(torch.complex64)
    image = _backproject_torch(
        profiles_t, positions, grid, range_bin_m, range_offset_m, cycles_per_m, torch_compile
    )
    return image if is_tensor else image.cpu().numpy()


def _as_numpy(range_profiles: Any) -> np.ndarray:
    if isinstance(range_profiles, torch.Tensor):
        range_profiles = range_profiles.detach().cpu().numpy()
    return np.asarray(range_profiles).astype(np.complex64, copy=False)


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


def _backproject_torch(
    profiles: torch.Tensor,
    positions: np.ndarray,
    grid: ImageGrid,
    range_bin_m: float,
    range_offset_m: float,
    cycles_per_m: float,
    torch_compile: bool = False,
) -> torch.Tensor:
    """Torch backend; see :func:`backproject`. Returns a complex64 tensor [H, W]."""
    device = profiles.device
    num_pulses, num_samples = profiles.shape
    height, width = grid.shape
    seg_px = segment_length_px(grid.dj)
    num_segments = -(-width // seg_px)

    # Segment centres (float64), one per (row, segment): tiles [T, 3].
    seg_center_col = np.arange(num_segments) * seg_px + (seg_px - 1) / 2
    centers = grid.pixel_to_world(np.arange(height)[:, None], seg_center_col[None, :]).reshape(-1, 3)
    centers_t = torch.as_tensor(centers, device=device)
    positions_t = torch.tensor(positions, device=device)
    dj_t = torch.tensor(grid.dj, device=device)
    offsets_px = torch.arange(seg_px, device=device, dtype=torch.float32) - (seg_px - 1) / 2
    inv_bin = 1.0 / range_bin_m
    # Scalars as a tensor, so a compiled pixel_sums is not specialised on their values.
    constants = torch.tensor([float(grid.dj @ grid.dj), inv_bin, cycles_per_m], device=device)
    pixel_sums = _compiled_pixel_sums() if torch_compile else _pixel_sums
    # Flattened (re, im) samples; pulse p's sample r is row p·R + r.
    samples_ri = torch.view_as_real(profiles.contiguous()).reshape(-1, 2)
    pulse_rows = torch.arange(num_pulses, device=device) * num_samples

    num_tiles = centers.shape[0]
    budget = _TORCH_CHUNK_ELEMENTS["cuda" if device.type == "cuda" else "cpu"]
    tiles_per_chunk = max(1, min(num_tiles, budget // seg_px))
    pulses_per_chunk = max(1, min(num_pulses, budget // (seg_px * tiles_per_chunk)))

    image = torch.zeros(num_tiles, seg_px, dtype=torch.complex64, device=device)
    for t0 in range(0, num_tiles, tiles_per_chunk):
        tiles = slice(t0, min(t0 + tiles_per_chunk, num_tiles))
        acc = torch.zeros(tiles.stop - t0, seg_px, 2, dtype=torch.float32, device=device)
        for p0 in range(0, num_pulses, pulses_per_chunk):
            pulses = slice(p0, min(p0 + pulses_per_chunk, num_pulses))
            # Per (segment, pulse), float64: [t, p].
            d = positions_t[None, pulses, :] - centers_t[tiles, None, :]
            r_ref = torch.linalg.vector_norm(d, dim=-1)
            b = 2.0 * (d @ dj_t)
            ref_cycles = r_ref * cycles_per_m
            ref_cycles = (ref_cycles - torch.floor(ref_cycles)).float()[..., None]
            # Linear phase term, turns per half pixel, reduced to [-0.5, 0.5).
            half_step = -0.25 * cycles_per_m * b / (r_ref + 1e-300)
            half_step = (half_step - torch.round(half_step)).float()[..., None]
            b_over_2r = (0.5 * b / (r_ref + 1e-300)).float()[..., None]
            base_index = ((r_ref - range_offset_m) * inv_bin).float()[..., None]
            sums = pixel_sums(
                b.float()[..., None],
                r_ref.float()[..., None],
                ref_cycles,
                half_step,
                b_over_2r,
                base_index,
                offsets_px,
                constants,
                samples_ri,
                pulse_rows[pulses, None],
                num_samples,
            )
            acc += sums
        image[tiles] = torch.view_as_complex(acc)
    return image.reshape(height, num_segments * seg_px)[:, :width].contiguous()


def _pixel_sums(
    b: torch.Tensor,
    r_ref: torch.Tensor,
    ref_cycles: torch.Tensor,
    half_step: torch.Tensor,
    b_over_2r: torch.Tensor,
    base_index: torch.Tensor,
    offsets_px: torch.Tensor,
    constants: torch.Tensor,
    samples_ri: torch.Tensor,
    pulse_rows: torch.Tensor,
    num_samples: int,
) -> torch.Tensor:
    """Per-pixel float32 work of one chunk, summed over its pulses: [t, seg_px, 2].

    The per-(segment, pulse) inputs are [t, p, 1] (``pulse_rows`` [p, 1]): see
    :mod:`zendar_dataset.sar.segments` for what they are.
    """
    dj_norm2, inv_bin, cycles_per_m = constants[0], constants[1], constants[2]
    m = offsets_px
    s = m * (m * dj_norm2 - b)
    inv_sum = 1.0 / (torch.sqrt(r_ref * r_ref + s) + r_ref + 1e-30)
    delta_r = s * inv_sum
    index = base_index + delta_r * inv_bin
    valid = (index >= 0) & (index <= num_samples - 1)
    index = index.clamp(0, num_samples - 1)
    lower = torch.floor(index).clamp(max=num_samples - 2)
    weight = (index - lower)[..., None]
    rows = lower.long() + pulse_rows
    lo = samples_ri[rows]
    value = (lo + weight * (samples_ri[rows + 1] - lo)) * valid[..., None]
    # R − R_ref minus its linear part m·g (g = −b / 2R_ref) is small and accurate
    # in float32; the linear part's phase comes reduced (2m is an odd integer).
    curved_r = (m * m * dj_norm2 + m * b_over_2r * delta_r) * inv_sum
    cycles = ref_cycles + (2 * m) * half_step + curved_r * cycles_per_m
    angle = (2 * math.pi) * (cycles - torch.round(cycles))
    cos, sin = torch.cos(angle), torch.sin(angle)
    # value · exp(−j·angle)
    return torch.stack(
        [
            (value[..., 0] * cos + value[..., 1] * sin).sum(dim=1),
            (value[..., 1] * cos - value[..., 0] * sin).sum(dim=1),
        ],
        dim=-1,
    )


@functools.cache
def _compiled_pixel_sums():
    # One fused kernel instead of ~40 elementwise passes over memory; shapes vary
    # between chunks, hence dynamic.
    return torch.compile(_pixel_sums, dynamic=True)
