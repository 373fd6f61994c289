"""The CPU backprojection kernel (numba): threads over row segments, SIMD over pixels.

Same float32 arithmetic as the torch backend (see :mod:`zendar_dataset.sar.segments`).
Two choices make it fast on a CPU:

- Loop order: for each row segment, pulses outside and the segment's pixels inside.
  The pixel loop is branch-free and LLVM vectorises it (AVX-512 where present); the
  pulse's profile (a few KiB) and the segment's accumulators stay in L1 cache.
  Pulses inside, pixels outside measured slower (benchmarks/bench_sar.py).
- ``sin``/``cos``: LLVM vectorises ``np.sin``/``np.cos`` only through Intel SVML,
  which numba builds commonly lack; a scalar libm call per pixel-pulse would cost
  more than the rest of the loop. :func:`_cis_neg_turns` is a polynomial on an
  exactly reduced argument (absolute error < 2e-7), which vectorises.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from zendar_dataset.sar.grid import ImageGrid
from zendar_dataset.sar.segments import segment_length_px

_TWO_PI = np.float32(2 * math.pi)


@numba.njit(inline="always", fastmath=True)
def _cis_neg_turns(turns):
    """``(cos θ, −sin θ)`` for ``θ = 2π·turns``, float32, vectorisable.

    ``turns`` is reduced by the nearest quarter turn (exact in float32 for the
    magnitudes used here, < 2**20), leaving ``|x| ≤ π/4`` for Taylor polynomials of
    degree 8 (cos) and 9 (sin); the quadrant then swaps and negates.
    """
    quarter = np.floor(turns * np.float32(4.0) + np.float32(0.5))
    x = (turns - quarter * np.float32(0.25)) * _TWO_PI
    x2 = x * x
    sin_x = x * (
        np.float32(1.0)
        + x2
        * (
            np.float32(-1.0 / 6)
            + x2 * (np.float32(1.0 / 120) + x2 * (np.float32(-1.0 / 5040) + x2 * np.float32(1.0 / 362880)))
        )
    )
    cos_x = np.float32(1.0) + x2 * (
        np.float32(-0.5)
        + x2 * (np.float32(1.0 / 24) + x2 * (np.float32(-1.0 / 720) + x2 * np.float32(1.0 / 40320)))
    )
    q = np.int32(quarter) & 3
    swap = (q & 1) == 1
    cos_sign = np.float32(1 - 2 * (((q + 1) >> 1) & 1))
    sin_sign = np.float32(1 - 2 * ((q >> 1) & 1))
    cos_t = cos_sign * (sin_x if swap else cos_x)
    sin_t = sin_sign * (cos_x if swap else sin_x)
    return cos_t, -sin_t


@numba.njit(parallel=True, fastmath=True, cache=True)
def _kernel(
    profiles_re,
    profiles_im,
    positions,
    origin,
    di,
    dj,
    height,
    width,
    seg_px,
    inv_bin,
    range_offset_m,
    cycles_per_m,
    out_re,
    out_im,
):
    num_pulses, num_samples = profiles_re.shape
    num_segments = (width + seg_px - 1) // seg_px
    dj_norm2 = np.float32(dj[0] * dj[0] + dj[1] * dj[1] + dj[2] * dj[2])
    inv_bin32 = np.float32(inv_bin)
    cycles32 = np.float32(cycles_per_m)
    last = np.float32(num_samples - 1)
    for tile in numba.prange(height * num_segments):
        row = tile // num_segments
        col0 = (tile % num_segments) * seg_px
        center_col = col0 + (seg_px - 1) / 2
        cx = origin[0] + row * di[0] + center_col * dj[0]
        cy = origin[1] + row * di[1] + center_col * dj[1]
        cz = origin[2] + row * di[2] + center_col * dj[2]
        offsets = np.empty(seg_px, dtype=np.float32)
        for q in range(seg_px):
            offsets[q] = np.float32(q - (seg_px - 1) / 2)
        acc_re = np.zeros(seg_px, dtype=np.float32)
        acc_im = np.zeros(seg_px, dtype=np.float32)
        for p in range(num_pulses):
            # float64 per (segment, pulse): see zendar_dataset.sar.segments.
            dx = positions[p, 0] - cx
            dy = positions[p, 1] - cy
            dz = positions[p, 2] - cz
            r_ref64 = math.sqrt(dx * dx + dy * dy + dz * dz)
            b = np.float32(2.0 * (dj[0] * dx + dj[1] * dy + dj[2] * dz))
            ref_turns64 = r_ref64 * cycles_per_m
            ref_turns = np.float32(ref_turns64 - math.floor(ref_turns64))
            base_index = np.float32((r_ref64 - range_offset_m) * inv_bin)
            r_ref = np.float32(r_ref64)
            r_ref2 = r_ref * r_ref
            prof_re = profiles_re[p]
            prof_im = profiles_im[p]
            for q in range(seg_px):
                m = offsets[q]
                s = m * (m * dj_norm2 - b)
                delta_r = s / (np.sqrt(r_ref2 + s) + r_ref)
                index = base_index + delta_r * inv_bin32
                inside = np.float32(1.0) if (index >= 0) and (index <= last) else np.float32(0.0)
                index = min(max(index, np.float32(0.0)), last)
                lower = min(np.int32(index), np.int32(num_samples - 2))
                weight = index - np.float32(lower)
                lo_re = prof_re[lower]
                lo_im = prof_im[lower]
                v_re = (lo_re + weight * (prof_re[lower + 1] - lo_re)) * inside
                v_im = (lo_im + weight * (prof_im[lower + 1] - lo_im)) * inside
                c, s_neg = _cis_neg_turns(ref_turns + delta_r * cycles32)
                # value · exp(−j·θ) = value · (c + j·s_neg)
                acc_re[q] += v_re * c - v_im * s_neg
                acc_im[q] += v_re * s_neg + v_im * c
        n = min(seg_px, width - col0)
        for q in range(n):
            out_re[row, col0 + q] = acc_re[q]
            out_im[row, col0 + q] = acc_im[q]


def backproject_numba(
    profiles: np.ndarray,
    positions: np.ndarray,
    grid: ImageGrid,
    range_bin_m: float,
    range_offset_m: float,
    cycles_per_m: float,
) -> np.ndarray:
    """Numba backend of :func:`zendar_dataset.sar.backprojection.backproject`.

    Inputs are validated by the caller: ``profiles`` [P, R] complex64,
    ``positions`` [P, 3] float64 in the grid's frame. Returns complex64 [H, W].
    """
    height, width = grid.shape
    out_re = np.empty((height, width), dtype=np.float32)
    out_im = np.empty((height, width), dtype=np.float32)
    _kernel(
        np.ascontiguousarray(profiles.real, dtype=np.float32),
        np.ascontiguousarray(profiles.imag, dtype=np.float32),
        np.ascontiguousarray(positions, dtype=np.float64),
        grid.origin,
        grid.di,
        grid.dj,
        height,
        width,
        segment_length_px(grid.dj),
        1.0 / range_bin_m,
        float(range_offset_m),
        float(cycles_per_m),
        out_re,
        out_im,
    )
    return out_re + np.complex64(1j) * out_im
