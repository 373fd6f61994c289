"""The torch backend of backprojection: CPU or CUDA, optionally fused by ``torch.compile``.

Same float32 arithmetic as the numba kernel (see :mod:`zendar_dataset.sar.segments`):
the float64 per-(segment, pulse) terms are formed for a chunk of segments and
pulses, then :func:`_pixel_sums` does the per-pixel work on ``[tiles, pulses,
segment]`` tensors and sums over the chunk's pulses.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import torch

from zendar_dataset.sar.grid import ImageGrid
from zendar_dataset.sar.segments import segment_length_px

# Elements of the [tiles, pulses, segment] float32 intermediates per chunk: large
# enough to amortise kernel launches on a GPU, small enough for CPU caches.
_CHUNK_ELEMENTS = {"cpu": 1 << 20, "cuda": 1 << 26}


def backproject_torch(
    profiles: torch.Tensor,
    positions: np.ndarray,
    grid: ImageGrid,
    range_bin_m: float,
    range_offset_m: float,
    cycles_per_m: float,
    torch_compile: bool = False,
) -> torch.Tensor:
    """Torch backend of :func:`zendar_dataset.sar.backprojection.backproject`.

    Inputs are validated by the caller: ``profiles`` [P, R] complex64 on the target
    device, ``positions`` [P, 3] float64 in the grid's frame. Returns a complex64
    tensor [H, W] on the profiles' device.
    """
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
    budget = _CHUNK_ELEMENTS["cuda" if device.type == "cuda" else "cpu"]
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
