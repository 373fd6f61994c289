"""Fast factorised backprojection: the same image as :func:`~zendar_dataset.sar.backprojection.backproject`
from fewer operations, by merging pulses into beams over shrinking image tiles.

The method is the quadtree factorisation of McCorkle & Rofheart (1996, "An order N² log N
backprojector algorithm for focusing wide-angle wide-bandwidth arbitrary-motion synthetic
aperture radar", Proc. SPIE 2747) in the form of Ulander, Hellsten & Stenström (2003, "Synthetic-
aperture radar processing using fast factorized back-projection", IEEE T-AES 39(3)), with
Cartesian tiles instead of polar sub-images (the output is a Cartesian grid, so no final
polar-to-Cartesian resampling is needed):

- A *beam* of a group of pulses (a sub-aperture with centre ``c``) toward an image tile is a
  function of range along the ray from ``c`` through the tile's centre:
  ``g(ρ) = Σ_p f_p(R_p(x_ρ)) exp(−j2πκ (R_p(x_ρ) − ρ))`` with ``x_ρ`` the point at range ``ρ`` on
  that ray, ``f_p`` the range profile of pulse ``p``, ``R_p(x) = |x − p|`` and ``κ = 2 f / c`` the
  two-way cycles per metre. For any pixel ``x`` of the tile,
  ``Σ_p f_p(R_p(x)) exp(−j2πκ R_p(x)) ≈ g(|x − c|) exp(−j2πκ |x − c|)``: the error is the
  change of ``R_p(x) − |x − c|`` across the tile, at most ``(l / 2)(h / R)`` for a sub-aperture of
  length ``l``, a tile of half-diagonal ``h`` at range ``R``: a phase error of ``2π l h / (λ R)``.
- Each image tile is first given beams of ``n0`` pulses each (the *leaf* step), ``n0`` the largest
  power of two that keeps that phase error under ``max_phase_error_rad`` at the tile's nearest range.
  Then, level by level, every tile is split into four and every pair of neighbouring beams merged
  into one beam toward each child tile (``l`` doubles while ``h`` halves, so the error bound stays
  the same), until tiles of ``final_tile_px`` pixels; each pixel then sums its tile's last beams.
- Tiles too close to the track for even ``n0 = 1`` are backprojected pulse by pulse (exact).

Cost per tile of ``s × s`` pixels and ``P`` pulses: ``P · N_ρ`` for the leaf beams (``N_ρ ≈ 1.4 s ·
pixel / Δρ`` range samples each), about as much again per merge level, and ``s² · P / (n0 · 2^L)``
for the pixels, instead of ``s² · P`` — the gain grows with the pixel size relative to the range
sampling and with the range; see docs/sar.md for measured figures.

Everything is float64 and pure array math (numba kernels, threads over the initial tiles).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from zendar_dataset.sar.backprojection import SPEED_OF_LIGHT_MPS, _check_inputs
from zendar_dataset.sar.grid import ImageGrid

DEFAULT_TILE_PX = 32
DEFAULT_FINAL_TILE_PX = 4
DEFAULT_MAX_PHASE_ERROR_RAD = 0.25
DEFAULT_BEAM_OVERSAMPLE = 2
MARGIN_SAMPLES = 2


def backproject_ffbp(
    range_profiles: np.ndarray,
    positions_m: np.ndarray,
    grid: ImageGrid,
    *,
    range_bin_m: float,
    center_frequency_hz: float,
    range_offset_m: float = 0.0,
    tile_px: int = DEFAULT_TILE_PX,
    final_tile_px: int = DEFAULT_FINAL_TILE_PX,
    max_phase_error_rad: float = DEFAULT_MAX_PHASE_ERROR_RAD,
    beam_oversample: int = DEFAULT_BEAM_OVERSAMPLE,
) -> np.ndarray:
    """Form a complex SAR image by fast factorised backprojection.

    Same inputs, conventions and output as :func:`~zendar_dataset.sar.backprojection.backproject`
    (``image[i, j] ≈ Σ_p interp(profile_p, R_pij) · exp(−j·4π·R_pij/λ)``); pulses are merged in the
    order given, so ``positions_m`` should follow the track (consecutive pulses close together).

    Parameters
    ----------
    range_profiles : numpy.ndarray, shape (P, R), complex64
        Range-compressed pulses; sample ``r`` at one-way range ``range_offset_m + r·range_bin_m``.
        Linear interpolation in range: oversample them (2–4×) as for the exact kernel.
    positions_m : numpy.ndarray, shape (P, 3), float64
        Phase centre of each pulse, in the grid's frame, metres.
    grid : ImageGrid
        Pixels to form.
    range_bin_m, center_frequency_hz, range_offset_m : float
        As for ``backproject``.
    tile_px : int
        Side of the initial tiles, pixels (a power of two).
    final_tile_px : int
        Side of the tiles whose pixels sum their beams directly (a power of two ≤ ``tile_px``).
    max_phase_error_rad : float
        Bound on the phase error of each beam approximation (see the module docstring); 0.25 rad
        costs at most ~0.1 dB of a beam's gain per level.
    beam_oversample : int
        Beams are sampled every ``range_bin_m / beam_oversample``: every level interpolates its
        sources linearly again, and finer beams keep the compounded loss of a peak under 0.5 dB.

    Returns
    -------
    numpy.ndarray, shape grid.shape, complex64
    """
    profiles = np.ascontiguousarray(range_profiles, dtype=np.complex64)
    positions = np.ascontiguousarray(positions_m, dtype=np.float64)
    _check_inputs(tuple(profiles.shape), positions, range_bin_m, center_frequency_hz, range_offset_m)
    problems = []
    for name, value in (("tile_px", tile_px), ("final_tile_px", final_tile_px)):
        if not (isinstance(value, (int, np.integer)) and value >= 1 and value & (value - 1) == 0):
            problems.append(f"{name} must be a power of two, got {value!r}")
    if not problems and final_tile_px > tile_px:
        problems.append(f"final_tile_px ({final_tile_px}) must not exceed tile_px ({tile_px})")
    if not (isinstance(beam_oversample, (int, np.integer)) and beam_oversample >= 1):
        problems.append(f"beam_oversample must be a positive integer, got {beam_oversample!r}")
    if not (math.isfinite(max_phase_error_rad) and max_phase_error_rad > 0):
        problems.append(f"max_phase_error_rad must be positive, got {max_phase_error_rad!r}")
    if problems:
        raise ValueError("backproject_ffbp: " + "; ".join(problems))
    height, width = grid.shape
    n_pulses = positions.shape[0]
    steps = np.linalg.norm(np.diff(positions, axis=0), axis=1)
    pulse_spacing = float(np.mean(steps)) if n_pulses > 1 else 0.0
    wavelength = SPEED_OF_LIGHT_MPS / center_frequency_hz
    out = np.zeros((height, width), dtype=np.complex64)
    _ffbp_kernel(
        profiles, positions, grid.origin, grid.di, grid.dj, height, width, int(tile_px), int(final_tile_px),
        float(range_bin_m), float(range_bin_m) / beam_oversample, float(range_offset_m),
        2.0 * center_frequency_hz / SPEED_OF_LIGHT_MPS,
        max_phase_error_rad * wavelength / (2.0 * math.pi), pulse_spacing, out,
    )
    return out


@numba.njit(inline="always")
def _cis_neg(turns):
    """``(cos, −sin)`` of ``2π turns`` for small ``|turns|`` (float64, vectorisable: no libm call).

    Reduced to the nearest quarter turn, then Taylor polynomials of degree 10/11 on
    ``|x| ≤ π/4`` (error < 1e-9).
    """
    quarter = np.floor(turns * 4.0 + 0.5)
    x = (turns - quarter * 0.25) * (2.0 * np.pi)
    x2 = x * x
    sin_x = x * (1.0 + x2 * (-1.0 / 6 + x2 * (1.0 / 120 + x2 * (-1.0 / 5040 + x2 * (1.0 / 362880 - x2 / 39916800)))))
    cos_x = 1.0 + x2 * (-0.5 + x2 * (1.0 / 24 + x2 * (-1.0 / 720 + x2 * (1.0 / 40320 - x2 / 3628800))))
    quadrant = quarter - 4.0 * np.floor(quarter * 0.25)
    swap = (quadrant == 1.0) | (quadrant == 3.0)
    cos_t = sin_x if swap else cos_x
    sin_t = cos_x if swap else sin_x
    cos_t = -cos_t if (quadrant == 1.0) | (quadrant == 2.0) else cos_t
    sin_t = -sin_t if quadrant >= 2.0 else sin_t
    return cos_t, -sin_t


@numba.njit
def _group_centers(positions, group):
    """Mean position ``[K, 3]`` of consecutive groups of ``group`` pulses."""
    n = positions.shape[0]
    k = (n + group - 1) // group
    centers = np.zeros((k, 3))
    for g in range(k):
        lo, hi = g * group, min((g + 1) * group, n)
        for p in range(lo, hi):
            for d in range(3):
                centers[g, d] += positions[p, d]
        for d in range(3):
            centers[g, d] /= hi - lo
    return centers


@numba.njit(inline="always")
def _add_along_ray(acc_re, acc_im, source, source_start, source_bin, a, b, rho_start, step, kappa,
                   index, weight, rot_re, rot_im):
    """``acc[r] += source(|x_r − s|) · exp(−j2πκ (|x_r − s| − ρ_r))`` for ``x_r`` at range ``ρ_r = rho_start + r·step``
    on a ray from ``c``, where ``s`` is a point with ``a = |s − c|²``, ``b = (s − c)·u``; ``source`` is sampled
    every ``source_bin`` from ``source_start``.

    ``|x_r − s| − ρ_r = (a − 2 ρ b) / (|x_r − s| + ρ)`` exactly, without cancellation.
    """
    n = acc_re.shape[0]
    last = source.shape[0] - 1
    for r in range(n):
        rho = rho_start + r * step
        dist = np.sqrt(rho * rho - 2.0 * rho * b + a)
        delta = (a - 2.0 * rho * b) / (dist + rho + 1e-300)
        position = (rho + delta - source_start) / source_bin
        inside = (position >= 0.0) & (position <= last)
        position = min(max(position, 0.0), last - 1e-9)
        lower = int(position)
        index[r] = lower
        weight[r] = position - lower
        c, s_neg = _cis_neg(kappa * delta)
        rot_re[r] = c * inside
        rot_im[r] = s_neg * inside
    for r in range(n):
        low = index[r]
        w = weight[r]
        value = source[low] * (1.0 - w) + source[min(low + 1, last)] * w
        acc_re[r] += value.real * rot_re[r] - value.imag * rot_im[r]
        acc_im[r] += value.real * rot_im[r] + value.imag * rot_re[r]


@numba.njit(parallel=True, cache=True, error_model="numpy")
def _ffbp_kernel(profiles, positions, origin, di, dj, height, width, tile_px, final_px,
                 bin_m, beam_bin, offset_m, kappa, range_error_budget, pulse_spacing, out):
    n_pulses = profiles.shape[0]
    tiles_i = (height + tile_px - 1) // tile_px
    tiles_j = (width + tile_px - 1) // tile_px
    norm_i = np.sqrt(di[0] ** 2 + di[1] ** 2 + di[2] ** 2)
    norm_j = np.sqrt(dj[0] ** 2 + dj[1] ** 2 + dj[2] ** 2)
    for tile in numba.prange(tiles_i * tiles_j):
        i0 = (tile // tiles_j) * tile_px
        j0 = (tile % tiles_j) * tile_px
        half = 0.5 * tile_px * (norm_i + norm_j)
        center = np.empty(3)
        for d in range(3):
            center[d] = origin[d] + (i0 + 0.5 * (tile_px - 1)) * di[d] + (j0 + 0.5 * (tile_px - 1)) * dj[d]
        # Nearest range from the track to the tile: sets how many pulses a beam may hold.
        nearest = 1e300
        for p in range(n_pulses):
            r = np.sqrt((positions[p, 0] - center[0]) ** 2 + (positions[p, 1] - center[1]) ** 2
                        + (positions[p, 2] - center[2]) ** 2)
            nearest = min(nearest, r)
        nearest = max(nearest - half, 0.0)
        group = 1
        while 2 * group <= n_pulses and 2 * group * pulse_spacing * half <= range_error_budget * nearest:
            group *= 2
        if group * pulse_spacing * half > range_error_budget * nearest or group == 1:
            _direct_tile(profiles, positions, origin, di, dj, height, width, i0, j0, tile_px,
                         bin_m, offset_m, kappa, out)
            continue
        # Leaf beams: groups of `group` pulses toward the whole tile.
        centers = _group_centers(positions, group)
        n_groups = centers.shape[0]
        n_rho = int(np.ceil(2.0 * half / beam_bin)) + 2 * MARGIN_SAMPLES + 1
        beams = np.zeros((1, n_groups, n_rho), dtype=np.complex128)
        rho0 = np.empty((1, n_groups))
        index = np.empty(n_rho, dtype=np.int64)
        weight = np.empty(n_rho)
        rot_re = np.empty(n_rho)
        rot_im = np.empty(n_rho)
        acc_re = np.empty(n_rho)
        acc_im = np.empty(n_rho)
        for g in range(n_groups):
            ux, uy, uz, dist = _axis(centers[g], center)
            start = dist - half - MARGIN_SAMPLES * beam_bin
            rho0[0, g] = start
            acc_re[:] = 0.0
            acc_im[:] = 0.0
            for p in range(g * group, min((g + 1) * group, n_pulses)):
                sx, sy, sz = positions[p, 0] - centers[g, 0], positions[p, 1] - centers[g, 1], positions[p, 2] - centers[g, 2]
                _add_along_ray(acc_re, acc_im, profiles[p], offset_m, bin_m, sx * sx + sy * sy + sz * sz,
                               sx * ux + sy * uy + sz * uz, start, beam_bin, kappa, index, weight, rot_re, rot_im)
            for r in range(n_rho):
                beams[0, g, r] = complex(acc_re[r], acc_im[r])
        # Merge levels: split every tile into four, pair the beams.
        size = tile_px
        while size > final_px and n_groups > 1:
            child = size // 2
            per_side = tile_px // child
            group *= 2
            new_centers = _group_centers(positions, group)
            new_groups = new_centers.shape[0]
            half_child = 0.5 * child * (norm_i + norm_j)
            new_rho = int(np.ceil(2.0 * half_child / beam_bin)) + 2 * MARGIN_SAMPLES + 1
            new_beams = np.zeros((per_side * per_side, new_groups, new_rho), dtype=np.complex128)
            new_rho0 = np.empty((per_side * per_side, new_groups))
            parent_side = tile_px // size
            acc_re = np.empty(new_rho)
            acc_im = np.empty(new_rho)
            for c in range(per_side * per_side):
                ci, cj = c // per_side, c % per_side
                parent = (ci // 2) * parent_side + cj // 2
                cc = np.empty(3)
                for d in range(3):
                    cc[d] = origin[d] + (i0 + ci * child + 0.5 * (child - 1)) * di[d] + (j0 + cj * child + 0.5 * (child - 1)) * dj[d]
                for g in range(new_groups):
                    ux, uy, uz, dist = _axis(new_centers[g], cc)
                    start = dist - half_child - MARGIN_SAMPLES * beam_bin
                    new_rho0[c, g] = start
                    acc_re[:] = 0.0
                    acc_im[:] = 0.0
                    for old in range(2 * g, min(2 * g + 2, n_groups)):
                        sx, sy, sz = centers[old, 0] - new_centers[g, 0], centers[old, 1] - new_centers[g, 1], centers[old, 2] - new_centers[g, 2]
                        _add_along_ray(acc_re, acc_im, beams[parent, old], rho0[parent, old], beam_bin,
                                       sx * sx + sy * sy + sz * sz, sx * ux + sy * uy + sz * uz, start, beam_bin, kappa,
                                       index, weight, rot_re, rot_im)
                    for r in range(new_rho):
                        new_beams[c, g, r] = complex(acc_re[r], acc_im[r])
            beams, rho0, centers, n_groups, size = new_beams, new_rho0, new_centers, new_groups, child
        # Pixels: each sums its tile's beams, g(|x − c|) exp(−j2πκ |x − c|).
        per_side = tile_px // size
        for c in range(per_side * per_side):
            ci, cj = c // per_side, c % per_side
            for a in range(size):
                i = i0 + ci * size + a
                if i >= height:
                    break
                for b in range(size):
                    j = j0 + cj * size + b
                    if j >= width:
                        break
                    x = origin[0] + i * di[0] + j * dj[0]
                    y = origin[1] + i * di[1] + j * dj[1]
                    z = origin[2] + i * di[2] + j * dj[2]
                    acc_r = 0.0
                    acc_i = 0.0
                    for g in range(n_groups):
                        rg = np.sqrt((x - centers[g, 0]) ** 2 + (y - centers[g, 1]) ** 2 + (z - centers[g, 2]) ** 2)
                        value = _interp(beams[c, g], (rg - rho0[c, g]) / beam_bin)
                        turns = kappa * rg
                        cos_t, sin_neg = _cis_neg(turns - np.floor(turns))
                        acc_r += value.real * cos_t - value.imag * sin_neg
                        acc_i += value.real * sin_neg + value.imag * cos_t
                    out[i, j] = complex(acc_r, acc_i)


@numba.njit(inline="always")
def _interp(values, index):
    """Linear interpolation of ``values [N]`` at fractional ``index``; 0 outside."""
    if index < 0.0 or index > values.shape[0] - 1:
        return 0j
    lower = min(int(index), values.shape[0] - 2)
    frac = index - lower
    return values[lower] * (1.0 - frac) + values[lower + 1] * frac


@numba.njit(inline="always")
def _axis(start, target):
    """Unit vector from ``start [3]`` to ``target [3]`` and the distance."""
    dx, dy, dz = target[0] - start[0], target[1] - start[1], target[2] - start[2]
    dist = np.sqrt(dx * dx + dy * dy + dz * dz)
    inv = 1.0 / max(dist, 1e-12)
    return dx * inv, dy * inv, dz * inv, dist


@numba.njit
def _direct_tile(profiles, positions, origin, di, dj, height, width, i0, j0, size, bin_m, offset_m, kappa, out):
    """Exact backprojection of one tile (tiles next to the track)."""
    for i in range(i0, min(i0 + size, height)):
        for j in range(j0, min(j0 + size, width)):
            x = origin[0] + i * di[0] + j * dj[0]
            y = origin[1] + i * di[1] + j * dj[1]
            z = origin[2] + i * di[2] + j * dj[2]
            acc_r = 0.0
            acc_i = 0.0
            for p in range(positions.shape[0]):
                rp = np.sqrt((x - positions[p, 0]) ** 2 + (y - positions[p, 1]) ** 2 + (z - positions[p, 2]) ** 2)
                value = _interp(profiles[p], (rp - offset_m) / bin_m)
                turns = kappa * rp
                cos_t, sin_neg = _cis_neg(turns - np.floor(turns))
                acc_r += value.real * cos_t - value.imag * sin_neg
                acc_i += value.real * sin_neg + value.imag * cos_t
            out[i, j] = complex(acc_r, acc_i)
