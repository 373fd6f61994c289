"""Backprojection throughput in G pixel·pulses/s: numpy reference, torch, numba kernel.

    python benchmarks/bench_sar.py                 # CPU: numpy per pulse, torch, numba (two loop orders)
    python benchmarks/bench_sar.py --device cuda   # adds torch on the GPU (eager and torch_compile)
    python benchmarks/bench_sar.py --ffbp          # only: fast factorised backprojection vs the numba kernel
    python benchmarks/bench_sar.py --paper-size    # only: the numba kernel at paper size, row tiles vs none

All methods image the same scene (paper geometry: 4 cm pixels, 2 m aperture, 77 GHz)
in the same run. The reference is plain float32 numpy per pulse (vectorised over pixels, one
thread); the float64 ``np.interp`` version is kept as a labelled strawman and as the accuracy
reference; slow methods run on a subset of pulses and are scaled, which is
fair since the work is linear in pulses. Accuracy of each method is reported
against the float64 numpy reference on a common subset (max |Δ| / max |image|);
random profiles make this a harsher test than a focused scene.
"""

from __future__ import annotations

import argparse
import math
import warnings

import numba
import numpy as np
import torch
from harness import print_environment, print_load_after, time_calls

from zendar_dataset.sar import ImageGrid, backproject
from zendar_dataset.sar.backprojection import SPEED_OF_LIGHT_MPS
from zendar_dataset.sar.backprojection_numba import _cis_neg_turns
from zendar_dataset.sar.ffbp import backproject_ffbp
from zendar_dataset.sar.segments import segment_length_px

CENTER_FREQUENCY_HZ = 77e9
RANGE_BIN_M = 0.0375
RANGE_OFFSET_M = 2.0


def make_scene(height: int, width: int, num_pulses: int, num_samples: int):
    rng = np.random.default_rng(0)
    profiles = (rng.standard_normal((num_pulses, num_samples)) + 1j * rng.standard_normal((num_pulses, num_samples)))
    positions = np.zeros((num_pulses, 3))
    positions[:, 0] = np.linspace(-1.0, 1.0, num_pulses)
    positions[:, 2] = 0.5
    grid = ImageGrid.axis_aligned([0.0, 14.0, 0.0], [0, 1, 0], [1, 0, 0], 0.04, (height, width))
    return profiles.astype(np.complex64), positions, grid


def numpy_per_pulse(profiles, positions, grid):
    """Strawman (and the accuracy reference): float64 numpy per pulse with ``np.interp``."""
    pixels = grid.pixel_centers()
    sample_ranges_m = RANGE_OFFSET_M + RANGE_BIN_M * np.arange(profiles.shape[1])
    cycles_per_m = 2 * CENTER_FREQUENCY_HZ / SPEED_OF_LIGHT_MPS
    image = np.zeros(grid.shape, dtype=np.complex128)
    for profile, position in zip(profiles, positions):
        r = np.linalg.norm(pixels - position, axis=-1)
        value = np.interp(r, sample_ranges_m, profile.real, left=0, right=0) + 1j * np.interp(
            r, sample_ranges_m, profile.imag, left=0, right=0
        )
        image += value * np.exp(-2j * np.pi * cycles_per_m * r)
    return image


def numpy_per_pulse_f32(profiles, positions, grid):
    """The plain reference: one vectorised numpy pass over all pixels per pulse in float32 /
    complex64 (the package's precision), linear interpolation by hand instead of ``np.interp``
    (float64 only, and real only)."""
    pixels = grid.pixel_centers().astype(np.float32)
    inv_bin = np.float32(1 / RANGE_BIN_M)
    cycles_per_m = np.float32(2 * CENTER_FREQUENCY_HZ / SPEED_OF_LIGHT_MPS)
    last = profiles.shape[1] - 1
    image = np.zeros(grid.shape, dtype=np.complex64)
    for profile, position in zip(profiles, positions.astype(np.float32)):
        r = np.linalg.norm(pixels - position, axis=-1)
        index = (r - np.float32(RANGE_OFFSET_M)) * inv_bin
        inside = (index >= 0) & (index <= last)
        low = np.clip(index.astype(np.int32), 0, last - 1)
        weight = index - low
        value = profile[low] + weight * (profile[low + 1] - profile[low])
        turns = r * cycles_per_m
        turns -= np.floor(turns)  # the fractional turn keeps float32 phase accurate
        image += np.where(inside, value * np.exp(np.complex64(-2j * np.pi) * turns), 0)
    return image


@numba.njit(parallel=True, fastmath=True, error_model="numpy")
def _pulses_inner_kernel(profiles, positions, origin, di, dj, height, width, seg_px, inv_bin, range_offset_m,
                         cycles_per_m, out):
    """The measured alternative loop order (docs/sar.md): per pixel, SIMD over pulses.

    Same arithmetic as the package kernel, which loops the other way (per pulse, SIMD over a
    segment's pixels); it lives here, not in the package, because it only serves this comparison.
    """
    num_pulses, num_samples = profiles.shape
    num_segments = (width + seg_px - 1) // seg_px
    dj_norm2 = np.float32(dj[0] * dj[0] + dj[1] * dj[1] + dj[2] * dj[2])
    last = np.float32(num_samples - 1)
    max_lower = np.uint32(num_samples - 2)
    tiny = np.float32(1e-30)
    for tile in numba.prange(height * num_segments):
        row = tile // num_segments
        col0 = (tile % num_segments) * seg_px
        center_col = col0 + (seg_px - 1) / 2
        b = np.empty(num_pulses, np.float32)
        r_ref = np.empty(num_pulses, np.float32)
        ref_turns = np.empty(num_pulses, np.float32)
        base_index = np.empty(num_pulses, np.float32)
        half_step = np.empty(num_pulses, np.float32)
        b_over_2r = np.empty(num_pulses, np.float32)
        for p in range(num_pulses):
            dx = positions[p, 0] - (origin[0] + row * di[0] + center_col * dj[0])
            dy = positions[p, 1] - (origin[1] + row * di[1] + center_col * dj[1])
            dz = positions[p, 2] - (origin[2] + row * di[2] + center_col * dj[2])
            r64 = math.sqrt(dx * dx + dy * dy + dz * dz)
            b[p] = 2.0 * (dj[0] * dx + dj[1] * dy + dj[2] * dz)
            turns = r64 * cycles_per_m
            ref_turns[p] = turns - math.floor(turns)
            base_index[p] = (r64 - range_offset_m) * inv_bin
            r_ref[p] = r64
            h = -0.25 * b[p] / (r64 + 1e-300) * cycles_per_m
            half_step[p] = h - math.floor(h + 0.5)
            b_over_2r[p] = 0.5 * b[p] / (r64 + 1e-300)
        lower = np.empty(num_pulses, np.uint32)
        weight = np.empty(num_pulses, np.float32)
        rot_re = np.empty(num_pulses, np.float32)
        rot_im = np.empty(num_pulses, np.float32)
        pairs_lo = np.empty(num_pulses, np.uint64)
        pairs_hi = np.empty(num_pulses, np.uint64)
        lo = pairs_lo.view(np.float32)
        hi = pairs_hi.view(np.float32)
        for q in range(min(seg_px, width - col0)):
            m = np.float32(q - (seg_px - 1) / 2)
            odd = np.float32(2 * q - (seg_px - 1))
            for p in range(num_pulses):
                s = m * (m * dj_norm2 - b[p])
                inv_sum = np.float32(1.0) / (np.sqrt(r_ref[p] * r_ref[p] + s) + r_ref[p] + tiny)
                delta_r = s * inv_sum
                curved_r = (m * m * dj_norm2 + m * b_over_2r[p] * delta_r) * inv_sum
                index = base_index[p] + delta_r * np.float32(inv_bin)
                inside = np.float32((index >= np.float32(0.0)) & (index <= last))
                index = min(max(index, np.float32(0.0)), last)
                low = min(np.uint32(index), max_lower)
                lower[p] = low
                weight[p] = index - np.float32(low)
                turns = ref_turns[p] + odd * half_step[p] + curved_r * np.float32(cycles_per_m)
                c, s_neg = _cis_neg_turns(turns)
                rot_re[p] = c * inside
                rot_im[p] = s_neg * inside
            for p in range(num_pulses):
                pairs_lo[p] = profiles[p, lower[p]]
                pairs_hi[p] = profiles[p, lower[p] + 1]
            acc_re = np.float32(0.0)
            acc_im = np.float32(0.0)
            for p in range(num_pulses):
                w = weight[p]
                v_re = lo[2 * p] + w * (hi[2 * p] - lo[2 * p])
                v_im = lo[2 * p + 1] + w * (hi[2 * p + 1] - lo[2 * p + 1])
                acc_re += v_re * rot_re[p] - v_im * rot_im[p]
                acc_im += v_re * rot_im[p] + v_im * rot_re[p]
            out[row, col0 + q] = acc_re + 1j * acc_im


def pulses_inner(profiles, positions, grid):
    out = np.empty(grid.shape, dtype=np.complex64)
    _pulses_inner_kernel(profiles.view(np.uint64), positions, grid.origin, grid.di, grid.dj, *grid.shape,
                         segment_length_px(grid.dj), 1 / RANGE_BIN_M, RANGE_OFFSET_M,
                         2 * CENTER_FREQUENCY_HZ / SPEED_OF_LIGHT_MPS, out)
    return out


def package(backend, device=None, torch_compile=False):
    def run(profiles, positions, grid):
        if device is not None:
            profiles = torch.from_numpy(profiles).to(device)
        image = backproject(profiles, positions, grid, range_bin_m=RANGE_BIN_M,
                            center_frequency_hz=CENTER_FREQUENCY_HZ, range_offset_m=RANGE_OFFSET_M,
                            backend=backend, device=device, torch_compile=torch_compile)
        if isinstance(image, torch.Tensor):
            if image.device.type == "cuda":
                torch.cuda.synchronize()
            image = image.cpu().numpy()
        return image
    return run


def focused_scene(size: int, aperture_m: float, bandwidth_hz: float = 3.75e9, upsample: int = 4):
    """Closed-form profiles (Dirichlet kernels, sampled ``upsample`` times per resolution cell) of 40 point
    targets 10-30 m from a ``aperture_m`` track at the corner radar's pulse spacing (1.1 mm), 4 cm pixels."""
    rng = np.random.default_rng(1)
    wavelength = SPEED_OF_LIGHT_MPS / CENTER_FREQUENCY_HZ
    num_pulses = int(aperture_m / 1.14e-3)
    track = np.zeros((num_pulses, 3))
    track[:, 0] = np.linspace(-aperture_m / 2, aperture_m / 2, num_pulses)
    track[:, 2] = 0.5
    bin_m = SPEED_OF_LIGHT_MPS / (2 * bandwidth_hz) / upsample
    ranges = np.arange(0.0, 40.0, bin_m)
    targets = np.stack([rng.uniform(-8, 8, 40), rng.uniform(12, 28, 40), np.full(40, 0.5)], axis=1)
    n = 1024
    profiles = np.zeros((num_pulses, ranges.size), dtype=np.complex128)
    for target in targets:
        r = np.linalg.norm(target - track, axis=1)
        half_x = 2 * np.pi * bandwidth_hz / (SPEED_OF_LIGHT_MPS * n) * (r[:, None] - ranges[None, :])
        sin_half = np.sin(half_x)
        kernel = np.where(np.abs(sin_half) < 1e-12, n, np.sin(n * half_x) / np.where(np.abs(sin_half) < 1e-12, 1, sin_half))
        profiles += np.exp(4j * np.pi * r / wavelength)[:, None] * kernel
    grid = ImageGrid.axis_aligned([0.0, 20.0, 0.5], [1, 0, 0], [0, 1, 0], 0.04, (size, size))
    return profiles.astype(np.complex64), track, grid, bin_m


def bench_ffbp(size: int, repeats: int) -> None:
    """Exact numba kernel vs fast factorised backprojection on focused paper-geometry scenes."""
    print(f"\nfast factorised backprojection vs the numba kernel: {size}x{size} pixels of 4 cm, 40 point targets "
          "10-30 m from the track, 3.75 GHz profiles sampled at 1 cm")
    print(f"{'aperture':>8s} {'pulses':>6s} {'method':34s} {'seconds median (min-max)':>26s} {'G pix*pulse/s':>14s} "
          f"{'x kernel':>9s} {'L2 diff':>8s} {'peak dB':>8s}")
    for aperture_m in (0.5, 2.0):
        profiles, track, grid, bin_m = focused_scene(size, aperture_m)
        pulses = track.shape[0]

        def exact():
            return backproject(profiles, track, grid, range_bin_m=bin_m, center_frequency_hz=CENTER_FREQUENCY_HZ)

        reference = exact()
        kernel_rate = None
        for name, fn in (
            ("numba kernel (exact)", exact),
            ("ffbp, tiles 32 -> 4", lambda: backproject_ffbp(profiles, track, grid, range_bin_m=bin_m,
                                                             center_frequency_hz=CENTER_FREQUENCY_HZ)),
            ("ffbp, tiles 32 -> 8", lambda: backproject_ffbp(profiles, track, grid, range_bin_m=bin_m,
                                                             center_frequency_hz=CENTER_FREQUENCY_HZ, final_tile_px=8)),
            ("ffbp, tiles 64 -> 8, 0.5 rad", lambda: backproject_ffbp(
                profiles, track, grid, range_bin_m=bin_m, center_frequency_hz=CENTER_FREQUENCY_HZ, tile_px=64,
                final_tile_px=8, max_phase_error_rad=0.5)),
        ):
            seconds = time_calls(fn, repeats)
            rate = size * size * pulses / seconds.median / 1e9
            kernel_rate = kernel_rate or rate
            image = fn()
            diff = np.linalg.norm(image - reference) / np.linalg.norm(reference)
            peak_db = 20 * np.log10(np.abs(image).max() / np.abs(reference).max())
            print(f"{aperture_m:8.1f} {pulses:6d} {name:34s} {seconds.text():>26s} {rate:14.3f} {rate / kernel_rate:9.2f} "
                  f"{diff:8.3f} {peak_db:8.2f}")


def bench_paper_size(rows: int, repeats: int) -> None:
    """The numba kernel on a band of a paper SAR image: ``rows`` × 1890 pixels of 4 cm, 1753 pulses of
    8,960 samples (1 cm, 4× upsampled 3.75 GHz profiles to 90 m: 126 MB, beyond every cache), with its
    row tiles and with one row segment per task (the kernel's earlier loop order), in the same run."""
    from zendar_dataset.sar import backprojection_numba

    rng = np.random.default_rng(0)
    pulses, samples, width, pixel_m = 1753, 8960, 1890, 0.04
    profiles = (rng.normal(size=(pulses, samples)) + 1j * rng.normal(size=(pulses, samples))).astype(np.complex64)
    positions = np.zeros((pulses, 3))
    positions[:, 0] = np.linspace(-1.0, 1.0, pulses)
    positions[:, 2] = 0.5
    grid = ImageGrid.axis_aligned([2.0 + pixel_m * width / 2, 3.0 + pixel_m * rows / 2, 0.0], [0.6, 0.8, 0.0],
                                  [-0.8, 0.6, 0.0], pixel_m, (rows, width))
    print(f"\nnumba kernel at paper size: {rows}x{width} pixels of 4 cm, {pulses} pulses x {samples} samples "
          f"({profiles.nbytes / 2**20:.0f} MiB of profiles), threads {numba.get_num_threads()}")
    print(f"{'rows per task':>14s} {'seconds median (min-max)':>26s} {'G pix*pulse/s':>14s}")
    default = backprojection_numba.ROWS_PER_TILE
    images = {}
    try:
        for tile_rows in (1, default):
            backprojection_numba.ROWS_PER_TILE = tile_rows

            def run():
                return backproject(profiles, positions, grid, range_bin_m=0.01, center_frequency_hz=CENTER_FREQUENCY_HZ)

            images[tile_rows] = run()
            seconds = time_calls(run, repeats)
            label = f"{tile_rows}" + (" (default)" if tile_rows == default else " (earlier)")
            print(f"{label:>14s} {seconds.text():>26s} {rows * width * pulses / seconds.median / 1e9:14.3f}")
    finally:
        backprojection_numba.ROWS_PER_TILE = default
    same = np.array_equal(images[1].view(np.uint64), images[default].view(np.uint64))
    print(f"images bit-identical: {same}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--size", type=int, default=512, help="image is size x size pixels")
    parser.add_argument("--pulses", type=int, default=512)
    parser.add_argument("--samples", type=int, default=1024)
    parser.add_argument("--repeats", type=int, default=5, help="timed runs per method (min / median / max)")
    parser.add_argument("--device", default="cpu", help="'cuda' adds torch on the GPU")
    parser.add_argument("--ffbp", action="store_true", help="only the fast factorised backprojection rows")
    parser.add_argument("--paper-size", action="store_true", help="only the numba kernel at paper size, tiled vs not")
    args = parser.parse_args()
    if args.paper_size:
        print_environment(("numpy", "numba"))
        bench_paper_size(256, args.repeats)
        print_load_after()
        return
    if args.ffbp:
        print_environment(("numpy", "numba"))
        bench_ffbp(args.size, args.repeats)
        print_load_after()
        return
    # torch.compile's internals warn about their own deprecated APIs.
    warnings.filterwarnings("ignore", category=DeprecationWarning)

    profiles, positions, grid = make_scene(args.size, args.size, args.pulses, args.samples)
    methods = [
        ("numpy float64, np.interp (strawman)", numpy_per_pulse, 8),
        ("numpy float32 per pulse (reference)", numpy_per_pulse_f32, 16),
        ("torch CPU", package("torch"), 32),
        ("torch CPU, torch_compile", package("torch", torch_compile=True), 64),
        ("numba, pulses inner", pulses_inner, args.pulses),
        ("numba kernel (package default)", package("numba"), args.pulses),
    ]
    if args.device != "cpu":
        if args.device.startswith("cuda") and not torch.cuda.is_available():
            print(f"--device {args.device}: no CUDA device here, GPU throughput not measured")
        else:
            methods.append((f"torch {args.device}", package("torch", args.device), args.pulses))
            methods.append((f"torch {args.device}, torch_compile", package("torch", args.device, True), args.pulses))

    # Accuracy on a common subset of pulses, against the float64 numpy reference.
    check = slice(0, 32)
    reference = numpy_per_pulse(profiles[check], positions[check], grid)
    scale = np.abs(reference).max()

    print_environment(("numpy", "numba", "torch"))
    print(f"image {args.size}x{args.size}, {args.pulses} pulses, {args.samples} range samples; threads: numpy 1 "
          f"(elementwise numpy is single-threaded), numba {numba.get_num_threads()}, torch {torch.get_num_threads()}")
    print(f"{'method':38s} {'pulses':>6s} {'seconds median (min-max)':>26s} {'G pix*pulse/s':>14s} "
          f"{'x f32 numpy':>12s} {'max|d|/max':>11s}")
    baseline = None
    for name, fn, pulses in methods:
        subset = slice(0, pulses)
        seconds = time_calls(lambda: fn(profiles[subset], positions[subset], grid), args.repeats)
        rate = args.size * args.size * pulses / seconds.median / 1e9
        if "reference" in name:
            baseline = rate
        ratio = f"{rate / baseline:12.1f}" if baseline else f"{'-':>12s}"
        error = np.abs(fn(profiles[check], positions[check], grid) - reference).max() / scale
        print(f"{name:38s} {pulses:6d} {seconds.text():>26s} {rate:14.3f} {ratio} {error:11.1e}")
    print_load_after()


if __name__ == "__main__":
    main()
