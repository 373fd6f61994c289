"""The CPU backprojection kernel (numba): threads over tiles of row segments, SIMD over pixels.

Same float32 arithmetic as the torch backend (see :mod:`zendar_dataset.sar.segments`).
What makes it fast on a CPU:

- Loop order: threads over tiles of ``ROWS_PER_TILE`` row segments; in a tile, pulses
  outside, then the tile's rows, then each segment's pixels. A pulse's profile window
  is read from memory once per tile (its rows' windows overlap) and the tile's
  accumulators (8 KiB) stay in L1. With one segment per tile every profile window was
  read once per segment: at paper size (1753 profiles of 72 KiB, 126 MB, beyond the
  caches) that made the kernel memory-bound (0.22 against 0.35 G pixel·pulses/s on
  256 × 1890 pixels, same run, shared machine). Pulses inside, pixels outside measured
  slower (benchmarks/bench_sar.py).
- Three pixel loops per pulse: geometry, weights and phase rotation (branch-free,
  vectorised by LLVM, AVX-512 where present); the indexed profile loads (scalar:
  LLVM declines gathers on some targets, e.g. AMD Zen 4, and would then leave the
  whole fused loop scalar; each complex sample moves as one 64-bit word); then
  interpolation and complex multiply-accumulate (vectorised).
- ``error_model="numpy"``: Python's division-by-zero check would block SIMD.
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
# Row segments per parallel tile: 16 rows of a 64-pixel segment keep the tile's accumulators
# (8 KiB) in L1 and its pulse windows (~2.6 m of range at 4 cm pixels) in L1/L2.
ROWS_PER_TILE = 16


@numba.njit(inline="always")
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
    # Quadrant 0..3 and its swap/negation as float compares: integer code here would
    # widen to int64 and cost more than the polynomials.
    quadrant = quarter - np.float32(4.0) * np.floor(quarter * np.float32(0.25))
    swap = (quadrant == np.float32(1.0)) | (quadrant == np.float32(3.0))
    negate_cos = (quadrant == np.float32(1.0)) | (quadrant == np.float32(2.0))
    negate_sin = quadrant >= np.float32(2.0)
    cos_t = sin_x if swap else cos_x
    sin_t = cos_x if swap else sin_x
    cos_t = -cos_t if negate_cos else cos_t
    sin_t = -sin_t if negate_sin else sin_t
    return cos_t, -sin_t


# No fastmath: with it, the freshly compiled kernel and the one loaded from numba's cache
# rounded a few pixels differently (measured: the same simulated scene differed by one
# float32 step between a first and a second run), which breaks byte-identical outputs.
# Without it the kernel is ~25% slower and still above 0.5 G pixel·pulses/s.
@numba.njit(parallel=True, error_model="numpy", cache=True)
def _kernel(
    profiles,
    positions_xyz,
    origin,
    di,
    dj,
    height,
    width,
    seg_px,
    rows_per_tile,
    inv_bin,
    range_offset_m,
    cycles_per_m,
    out_re,
    out_im,
):
    """Fill ``out_re``/``out_im`` [H, W] float32.

    ``profiles`` is [P, R] uint64 (complex64 bit patterns), ``positions_xyz`` [3, P]
    float64, ``origin``/``di``/``dj`` the grid's float64 vectors. Each parallel tile is
    ``rows_per_tile`` row segments stacked along ``di``; every pixel sums its pulses in
    order ``0 … P−1``, so the tile shape changes speed only, never a bit of the result.
    """
    num_pulses, num_samples = profiles.shape
    num_segments = (width + seg_px - 1) // seg_px
    num_row_blocks = (height + rows_per_tile - 1) // rows_per_tile
    dj_norm2 = np.float32(dj[0] * dj[0] + dj[1] * dj[1] + dj[2] * dj[2])
    inv_bin32 = np.float32(inv_bin)
    cycles32 = np.float32(cycles_per_m)
    last = np.float32(num_samples - 1)
    max_lower = np.uint32(num_samples - 2)
    # Keeps 0/0 finite when a pulse sits exactly on a segment centre.
    tiny = np.float32(1e-30)
    for tile in numba.prange(num_row_blocks * num_segments):
        row0 = (tile // num_segments) * rows_per_tile
        n_rows = min(rows_per_tile, height - row0)
        col0 = (tile % num_segments) * seg_px
        center_col = col0 + (seg_px - 1) / 2
        offsets = np.empty(seg_px, dtype=np.float32)
        odd = np.empty(seg_px, dtype=np.float32)
        for q in range(seg_px):
            offsets[q] = np.float32(q - (seg_px - 1) / 2)
            odd[q] = np.float32(2 * q - (seg_px - 1))
        acc_re = np.zeros((n_rows, seg_px), dtype=np.float32)
        acc_im = np.zeros((n_rows, seg_px), dtype=np.float32)
        lower = np.empty(seg_px, dtype=np.uint32)
        weight = np.empty(seg_px, dtype=np.float32)
        rot_re = np.empty(seg_px, dtype=np.float32)
        rot_im = np.empty(seg_px, dtype=np.float32)
        # (re, im) float32 pairs moved as one 64-bit word each.
        pairs_lo = np.empty(seg_px, dtype=np.uint64)
        pairs_hi = np.empty(seg_px, dtype=np.uint64)
        lo = pairs_lo.view(np.float32)
        hi = pairs_hi.view(np.float32)
        # float64 per (segment, pulse), SIMD over pulses: see zendar_dataset.sar.segments.
        b_all = np.empty((n_rows, num_pulses), dtype=np.float32)
        r_ref_all = np.empty((n_rows, num_pulses), dtype=np.float32)
        ref_turns_all = np.empty((n_rows, num_pulses), dtype=np.float32)
        half_step_all = np.empty((n_rows, num_pulses), dtype=np.float32)
        base_index_all = np.empty((n_rows, num_pulses), dtype=np.float32)
        b_over_2r_all = np.empty((n_rows, num_pulses), dtype=np.float32)
        for k in range(n_rows):
            row = row0 + k
            cx = origin[0] + row * di[0] + center_col * dj[0]
            cy = origin[1] + row * di[1] + center_col * dj[1]
            cz = origin[2] + row * di[2] + center_col * dj[2]
            for p in range(num_pulses):
                dx = positions_xyz[0, p] - cx
                dy = positions_xyz[1, p] - cy
                dz = positions_xyz[2, p] - cz
                r_ref64 = np.sqrt(dx * dx + dy * dy + dz * dz)
                b64 = 2.0 * (dj[0] * dx + dj[1] * dy + dj[2] * dz)
                inv_r64 = 1.0 / (r_ref64 + 1e-300)
                ref_turns64 = r_ref64 * cycles_per_m
                # Linear phase term, turns per half pixel, reduced to [-0.5, 0.5).
                half_step64 = -0.25 * cycles_per_m * b64 * inv_r64
                b_all[k, p] = b64
                r_ref_all[k, p] = r_ref64
                ref_turns_all[k, p] = ref_turns64 - np.floor(ref_turns64)
                half_step_all[k, p] = half_step64 - np.floor(half_step64 + 0.5)
                base_index_all[k, p] = (r_ref64 - range_offset_m) * inv_bin
                b_over_2r_all[k, p] = 0.5 * b64 * inv_r64
        # Pulses outside the tile's rows: a pulse's profile is read from memory once per tile
        # (its rows' windows overlap) instead of once per row segment, which at paper size
        # (1753 profiles of 72 KiB, far beyond the caches) was the kernel's bottleneck.
        for p in range(num_pulses):
            profile = profiles[p]
            for k in range(n_rows):
                b = b_all[k, p]
                r_ref = r_ref_all[k, p]
                r_ref2 = r_ref * r_ref
                ref_turns = ref_turns_all[k, p]
                half_step_turns = half_step_all[k, p]
                base_index = base_index_all[k, p]
                b_over_2r = b_over_2r_all[k, p]
                # Geometry, interpolation weights and phase rotation: SIMD.
                for q in range(seg_px):
                    m = offsets[q]
                    s = m * (m * dj_norm2 - b)
                    inv_sum = np.float32(1.0) / (np.sqrt(r_ref2 + s) + r_ref + tiny)
                    delta_r = s * inv_sum
                    index = base_index + delta_r * inv_bin32
                    # R − R_ref minus its linear part m·g, g = −b / 2R_ref: small, so
                    # accurate in float32; the linear part's phase comes reduced.
                    curved_r = (m * m * dj_norm2 + m * b_over_2r * delta_r) * inv_sum
                    turns = ref_turns + odd[q] * half_step_turns + curved_r * cycles32
                    inside = np.float32((index >= np.float32(0.0)) & (index <= last))
                    index = min(max(index, np.float32(0.0)), last)
                    low = min(np.uint32(index), max_lower)
                    lower[q] = low
                    weight[q] = index - np.float32(low)
                    c, s_neg = _cis_neg_turns(turns)
                    rot_re[q] = c * inside
                    rot_im[q] = s_neg * inside
                # Indexed loads: scalar, as gathers do not pay on every x86 target.
                for q in range(seg_px):
                    low = lower[q]
                    pairs_lo[q] = profile[low]
                    pairs_hi[q] = profile[low + 1]
                # Linear interpolation and complex multiply-accumulate: SIMD.
                row_re = acc_re[k]
                row_im = acc_im[k]
                for q in range(seg_px):
                    w = weight[q]
                    v_re = lo[2 * q] + w * (hi[2 * q] - lo[2 * q])
                    v_im = lo[2 * q + 1] + w * (hi[2 * q + 1] - lo[2 * q + 1])
                    # value · exp(−j·θ) = value · (rot_re + j·rot_im)
                    row_re[q] += v_re * rot_re[q] - v_im * rot_im[q]
                    row_im[q] += v_re * rot_im[q] + v_im * rot_re[q]
        n = min(seg_px, width - col0)
        for k in range(n_rows):
            for q in range(n):
                out_re[row0 + k, col0 + q] = acc_re[k, q]
                out_im[row0 + k, col0 + q] = acc_im[k, q]


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
        np.ascontiguousarray(profiles, dtype=np.complex64).view(np.uint64),
        np.ascontiguousarray(positions.T, dtype=np.float64),
        grid.origin,
        grid.di,
        grid.dj,
        height,
        width,
        segment_length_px(grid.dj),
        ROWS_PER_TILE,
        1.0 / range_bin_m,
        float(range_offset_m),
        float(cycles_per_m),
        out_re,
        out_im,
    )
    return out_re + np.complex64(1j) * out_im
