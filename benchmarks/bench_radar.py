"""Radar signal-processing speed: range-Doppler, CFAR, DOA (CPU), and the batched chain (--device cuda).

Run: ``python benchmarks/bench_radar.py [--repeat 30] [--device cuda --batch 64]``.
Each row is timed against a plain reference implementation measured in the same run;
times are the median (and best) of ``--repeat`` runs, in milliseconds.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from zendar_dataset.radar.cfar import CfarWindow, cfar_2d, default_os_rank, detect, ordered_statistic_reference
from zendar_dataset.radar.doa import estimate_azimuth, steering_vectors
from zendar_dataset.radar.fmcw import SPEED_OF_LIGHT_MPS, FmcwParams
from zendar_dataset.radar.range_doppler import range_doppler

GUARD, TRAIN = (2, 2), (8, 4)


def timeit(fn, repeat: int) -> tuple[float, float]:
    fn()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times) * 1e3, min(times) * 1e3


# --- plain references ----------------------------------------------------------------


def reference_range_doppler(raw: np.ndarray) -> np.ndarray:
    """numpy.fft (single-threaded), explicit window products and fftshift."""
    w_r = np.hanning(raw.shape[1] + 1)[:-1]
    w_d = np.hanning(raw.shape[0] + 1)[:-1]
    spec = np.fft.fft(raw * w_r[None, :, None], axis=1)
    spec = np.fft.fftshift(np.fft.fft(spec * w_d[:, None, None], axis=0), axes=0)
    return spec.transpose(1, 0, 2)


def reference_cfar_per_cell(power: np.ndarray, method: str, n_cells: int = 300) -> float:
    """Seconds per map of a per-cell Python loop over the training ring, extrapolated from ``n_cells`` cells."""
    window = CfarWindow(*GUARD, *TRAIN)
    off = window.offsets()
    rank = default_os_rank(window.n_train)
    n_r, n_d = power.shape
    rng = np.random.default_rng(0)
    cells = np.c_[rng.integers(window.half_range, n_r - window.half_range, n_cells), rng.integers(0, n_d, n_cells)]
    t0 = time.perf_counter()
    for r, d in cells:
        ring = power[r + off[:, 0], (d + off[:, 1]) % n_d]
        if method == "ca":
            stat = ring.mean()
        elif method == "os":
            stat = np.partition(ring, rank - 1)[rank - 1]
        else:
            near = (off[:, 0] < 0) | ((off[:, 0] == 0) & (off[:, 1] < 0))
            pick = min if method == "so" else max
            stat = pick(ring[near].mean(), ring[~near].mean())
        _ = power[r, d] > 3.0 * stat
    return (time.perf_counter() - t0) / n_cells * power.size


def reference_cfar_rows(power: np.ndarray) -> np.ndarray:
    """OpenRadar-style 1-D CA-CFAR run along range for every Doppler column (np.convolve per column)."""
    n_train, n_guard = TRAIN[0], GUARD[0]
    kernel = np.r_[np.ones(n_train), np.zeros(2 * n_guard + 1), np.ones(n_train)] / (2 * n_train)
    out = np.empty_like(power, dtype=bool)
    for d in range(power.shape[1]):
        col = power[:, d]
        noise = np.convolve(np.pad(col, n_train + n_guard, mode="reflect"), kernel, mode="valid")
        out[:, d] = col > 3.0 * noise
    return out


def reference_doa(snapshots: np.ndarray, rx: np.ndarray, wavelength: float) -> np.ndarray:
    """Per-detection loop: Bartlett on a 0.1-degree grid."""
    grid = np.deg2rad(np.arange(-90, 90.05, 0.1))
    steer = steering_vectors(grid, rx, wavelength)
    return np.array([grid[np.argmax(np.abs(steer.conj() @ x) ** 2)] for x in snapshots])


# --- runs ----------------------------------------------------------------------------------


def cpu_rows(repeat: int) -> list[tuple[str, float, float, float, str]]:
    rng = np.random.default_rng(0)
    rows = []
    raw = (rng.standard_normal((256, 512, 4)) + 1j * rng.standard_normal((256, 512, 4))).astype(np.complex64)
    ours = timeit(lambda: range_doppler(raw, workers=-1), repeat)
    ref = timeit(lambda: reference_range_doppler(raw), max(3, repeat // 3))
    rows.append(("range-Doppler 4x256x512 (scipy.fft, workers=-1)", *ours, ref[0], "numpy.fft, 1 thread"))

    power = rng.exponential(size=(512, 256))
    row_ref = timeit(lambda: reference_cfar_rows(power), max(3, repeat // 3))[0]
    for method in ("ca", "so", "go", "os"):
        ours = timeit(lambda: cfar_2d(power, method=method, guard=GUARD, train=TRAIN, pfa=1e-4), repeat)
        loop = reference_cfar_per_cell(power, method) * 1e3
        rows.append((f"{method.upper()}-CFAR 512x256, {CfarWindow(*GUARD, *TRAIN).n_train} training cells", *ours, loop, "per-cell loop (extrapolated)"))
        if method == "ca":
            rows.append(("CA-CFAR 512x256 (1-D rows, no Doppler training)", *ours, row_ref, "OpenRadar-style per-column 1-D CA"))
        if method == "os":
            window = CfarWindow(*GUARD, *TRAIN)
            rank_ref = timeit(lambda: ordered_statistic_reference(power, window, default_os_rank(window.n_train)), 2)[0]
            rows.append(("OS-CFAR 512x256 (detection mask)", *ours, rank_ref, "scipy.ndimage.rank_filter ring"))
            full = timeit(lambda: cfar_2d(power, method="os", guard=GUARD, train=TRAIN, pfa=1e-4).threshold, 3)
            rows.append(("OS-CFAR 512x256 with the full threshold map", *full, rank_ref, "scipy.ndimage.rank_filter ring"))
            rows.append(("OS-CFAR 512x256 (detection mask)", *ours, full[0], "per-cell selection (threshold map)"))
            ours = timeit(lambda: detect(power, range_bin_m=0.2, doppler_bin_mps=0.1, method="os", guard=GUARD, train=TRAIN), repeat)
            rows.append(("OS detect() 512x256 (mask + local max + SNR)", *ours, full[0], "per-cell selection (threshold map)"))

    wavelength = SPEED_OF_LIGHT_MPS / 77e9
    rx = np.c_[np.zeros(4), np.arange(4) * wavelength / 2, np.zeros(4)]
    truth = np.deg2rad(rng.uniform(-60, 60, 100))
    snaps = steering_vectors(truth, rx, wavelength) + 0.1 * (rng.standard_normal((100, 4)) + 1j * rng.standard_normal((100, 4)))
    ref = timeit(lambda: reference_doa(snaps, rx, wavelength), max(3, repeat // 3))
    for method in ("bartlett", "capon", "music"):
        ours = timeit(lambda: estimate_azimuth(snaps, rx, wavelength, method=method), repeat)
        rows.append((f"DOA {method}, 100 detections", *ours, ref[0], "per-detection Bartlett loop"))
    return rows


def cuda_rows(batch: int, repeat: int) -> list[tuple[str, float, float, float, str]]:
    import torch

    from zendar_dataset.radar.pipeline import RadarChain

    if not torch.cuda.is_available():
        print("--device cuda: no CUDA device here; the batched chain was not measured.")
        return []
    wavelength = SPEED_OF_LIGHT_MPS / 77e9
    params = FmcwParams(77e9, 853e6, 20e6, 512, 256, 30e-6, np.c_[np.zeros(4), np.arange(4) * wavelength / 2, np.zeros(4)])
    frames = torch.randn(batch, 256, 512, 4, dtype=torch.complex64, device="cuda")
    rows = []
    for method in ("ca", "os"):
        chain = RadarChain(params, device="cuda", cfar={"method": method})

        def run() -> None:
            chain.from_raw(frames)
            torch.cuda.synchronize()

        ours = timeit(run, repeat)
        rows.append((f"chain {method.upper()} + Bartlett, batch {batch} (frames/s = {batch / ours[0] * 1e3:,.0f})", *ours, float("nan"), "-"))
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=30)
    parser.add_argument("--device", choices=("cpu", "cuda"), default="cpu")
    parser.add_argument("--batch", type=int, default=64)
    args = parser.parse_args()
    rows = cuda_rows(args.batch, args.repeat) if args.device == "cuda" else cpu_rows(args.repeat)
    print(f"{'case':<62} {'median ms':>10} {'best ms':>9} {'ref ms':>10} {'ratio':>8}  reference")
    for name, median, best, ref, ref_name in rows:
        print(f"{name:<62} {median:>10.3f} {best:>9.3f} {ref:>10.2f} {ref / median:>7.1f}x  {ref_name}")


if __name__ == "__main__":
    main()
