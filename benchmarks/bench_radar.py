"""Radar signal-processing speed: range-Doppler, CFAR, DOA (CPU), and the batched chain (--device cuda).

Run: ``python benchmarks/bench_radar.py [--repeat 30] [--device cuda --batch 64]``.

Every row times the package against, in the same run and interleaved call by call:

* the best plain implementation a competent user would write with numpy/scipy
  (vectorised, same dtype, same thread count), checked to give the same result;
* the peer package where one exists: OpenRadar (PyPI ``openradar``, module ``mmwave``)
  for 1-D CA- and OS-CFAR, on the same configuration, with the detections compared;
* strawmen (per-cell Python loops, float64 single-threaded FFTs) only where labelled so.

Threads: ``range_doppler`` and the plain ``scipy.fft`` reference both use
``workers=-1`` (every CPU); the package's CFAR kernels are serial numba, and
``scipy.ndimage`` filters and OpenRadar are single-threaded; DOA on both sides is numpy
with the same BLAS threads. Times are min / median / max over ``--repeat`` calls, ms.
"""

from __future__ import annotations

import argparse
import os

import numpy as np
import scipy.fft
import scipy.ndimage
import threadpoolctl
from harness import Spread, interleaved, missing_peer, print_environment, print_load_after, time_calls

from zendar_dataset.radar.cfar import CfarWindow, cfar_2d, cfar_alpha, default_os_rank
from zendar_dataset.radar.doa import estimate_azimuth, steering_vectors
from zendar_dataset.radar.fmcw import SPEED_OF_LIGHT_MPS, FmcwParams
from zendar_dataset.radar.range_doppler import range_doppler, window_values

GUARD, TRAIN = (2, 2), (8, 4)
PFA = 1e-4
# 1-D CFAR along range, the configuration OpenRadar's CFAR functions take.
GUARD_1D, TRAIN_1D = 2, 8

Row = tuple[str, Spread, str, Spread | None, str]  # case, package, reference name, reference, note

try:
    import mmwave.dsp.cfar as openradar_cfar
except ImportError:
    openradar_cfar = None


# --- range-Doppler -------------------------------------------------------------------------


def plain_range_doppler(raw: np.ndarray, window: np.ndarray) -> np.ndarray:
    """scipy.fft on complex64 with a float32 window, every thread, fftshift along Doppler."""
    spec = scipy.fft.fft2(raw * window, axes=(0, 1), workers=-1)
    return scipy.fft.fftshift(spec, axes=0).transpose(1, 0, 2)


def strawman_range_doppler(raw: np.ndarray) -> np.ndarray:
    """Strawman: numpy.fft (one thread) with float64 windows, which turn the data complex128."""
    w_r = np.hanning(raw.shape[1] + 1)[:-1]
    w_d = np.hanning(raw.shape[0] + 1)[:-1]
    spec = np.fft.fft(raw * w_r[None, :, None], axis=1)
    spec = np.fft.fftshift(np.fft.fft(spec * w_d[:, None, None], axis=0), axes=0)
    return spec.transpose(1, 0, 2)


def range_doppler_rows(rng: np.random.Generator, repeat: int) -> list[Row]:
    raw = (rng.standard_normal((256, 512, 4)) + 1j * rng.standard_normal((256, 512, 4))).astype(np.complex64)
    window = (window_values("hann", 256)[:, None] * window_values("hann", 512)[None, :]).astype(np.float32)[..., None]
    ours = range_doppler(raw, workers=-1)
    plain = plain_range_doppler(raw, window)
    scale = np.abs(plain).max()
    assert np.abs(ours - plain).max() <= 1e-5 * scale, "plain range-Doppler differs from the package"
    t = interleaved(
        {
            "ours": lambda: range_doppler(raw, workers=-1),
            "plain": lambda: plain_range_doppler(raw, window),
            "straw": lambda: strawman_range_doppler(raw),
        },
        repeat,
    )
    return [
        ("range-Doppler 4x256x512 c64", t["ours"], "plain scipy.fft c64, 2 threads", t["plain"], "same output"),
        ("", t["ours"], "strawman: numpy.fft f64 window, 1 thread", t["straw"], "labelled strawman"),
    ]


# --- 2-D CFAR ------------------------------------------------------------------------------


def _padded(power: np.ndarray, window: CfarWindow) -> np.ndarray:
    """The package's edges: range mirrored (numpy 'reflect'), Doppler circular."""
    padded = np.pad(power, ((window.half_range, window.half_range), (0, 0)), mode="reflect")
    return np.pad(padded, ((0, 0), (window.half_doppler, window.half_doppler)), mode="wrap")


def _crop(filtered: np.ndarray, window: CfarWindow, shape: tuple[int, int]) -> np.ndarray:
    return filtered[window.half_range : window.half_range + shape[0], window.half_doppler : window.half_doppler + shape[1]]


def plain_cfar_mask(power: np.ndarray, method: str, window: CfarWindow, alpha: float) -> np.ndarray:
    """Vectorised numpy CA / SO / GO: every box sum from one summed-area table (two cumsums)
    over the padded map, sliced for all cells at once."""
    padded = _padded(power, window)
    table = np.zeros((padded.shape[0] + 1, padded.shape[1] + 1))
    table[1:, 1:] = padded.cumsum(axis=0).cumsum(axis=1)
    n_r, n_d = power.shape
    hr, hd, gr, gd = window.half_range, window.half_doppler, window.guard_range, window.guard_doppler

    def box(r0: int, r1: int, d0: int, d1: int) -> np.ndarray:
        """Sum over range offsets r0..r1 and Doppler offsets d0..d1 of every cell (inclusive)."""
        rows_hi, rows_lo = slice(hr + r1 + 1, hr + r1 + 1 + n_r), slice(hr + r0, hr + r0 + n_r)
        cols_hi, cols_lo = slice(hd + d1 + 1, hd + d1 + 1 + n_d), slice(hd + d0, hd + d0 + n_d)
        return table[rows_hi, cols_hi] - table[rows_lo, cols_hi] - table[rows_hi, cols_lo] + table[rows_lo, cols_lo]

    total = box(-hr, hr, -hd, hd) - box(-gr, gr, -gd, gd)
    if method == "ca":
        noise = total / window.n_train
    else:
        near = box(-hr, -1, -hd, hd) + box(0, 0, -hd, -gd - 1)
        if gr > 0:
            near -= box(-gr, -1, -gd, gd)
        halves = (near, total - near)
        noise = (np.minimum(*halves) if method == "so" else np.maximum(*halves)) / (window.n_train // 2)
    return power > alpha * noise


def strawman_cfar_per_cell(power: np.ndarray, method: str, window: CfarWindow, n_cells: int = 300) -> Spread:
    """Strawman: a per-cell Python loop over the training ring, extrapolated from ``n_cells`` cells."""
    off = window.offsets()
    rank = default_os_rank(window.n_train)
    n_r, n_d = power.shape
    rng = np.random.default_rng(0)
    cells = np.c_[rng.integers(window.half_range, n_r - window.half_range, n_cells), rng.integers(0, n_d, n_cells)]
    near = (off[:, 0] < 0) | ((off[:, 0] == 0) & (off[:, 1] < 0))

    def run() -> None:
        for r, d in cells:
            ring = power[r + off[:, 0], (d + off[:, 1]) % n_d]
            if method == "ca":
                stat = ring.mean()
            elif method == "os":
                stat = np.partition(ring, rank - 1)[rank - 1]
            else:
                stat = (min if method == "so" else max)(ring[near].mean(), ring[~near].mean())
            _ = power[r, d] > 3.0 * stat

    return time_calls(run, 3, warmup=0).scaled(power.size / n_cells)


def os_statistic_map(power: np.ndarray, window: CfarWindow, rank: int) -> np.ndarray:
    """scipy.ndimage.rank_filter with the ring footprint: the OS statistic at every cell."""
    footprint = np.zeros((2 * window.half_range + 1, 2 * window.half_doppler + 1), dtype=bool)
    off = window.offsets()
    footprint[off[:, 0] + window.half_range, off[:, 1] + window.half_doppler] = True
    filtered = scipy.ndimage.rank_filter(_padded(power, window), rank - 1, footprint=footprint, mode="constant")
    return _crop(filtered, window, power.shape)


def cfar_rows(rng: np.random.Generator, repeat: int) -> list[Row]:
    power = rng.exponential(size=(512, 256))
    power[rng.integers(0, 512, 60), rng.integers(0, 256, 60)] *= 200.0  # targets to detect
    window = CfarWindow(*GUARD, *TRAIN)
    rows: list[Row] = []
    for method in ("ca", "so", "go"):
        alpha = cfar_alpha(method, window.n_train, PFA)
        ours = cfar_2d(power, method=method, guard=GUARD, train=TRAIN, pfa=PFA)
        plain = plain_cfar_mask(power, method, window, alpha)
        differ = int((ours.mask != plain).sum())
        t = interleaved(
            {
                "ours": lambda: cfar_2d(power, method=method, guard=GUARD, train=TRAIN, pfa=PFA),
                "plain": lambda: plain_cfar_mask(power, method, window, alpha),
            },
            repeat,
        )
        name = f"{method.upper()}-CFAR 512x256, {window.n_train} training cells"
        rows.append((name, t["ours"], "plain numpy summed-area table", t["plain"],
                     f"{int(ours.mask.sum())} detections, {differ} differ"))
        rows.append(("", t["ours"], "strawman: per-cell Python loop", strawman_cfar_per_cell(power, method, window),
                     "labelled strawman, extrapolated"))

    # OS: the full statistic map on both sides (same output), then the detection mask alone.
    rank = default_os_rank(window.n_train)
    alpha = cfar_alpha("os", window.n_train, PFA)
    ours = cfar_2d(power, method="os", guard=GUARD, train=TRAIN, pfa=PFA)
    reference_map = os_statistic_map(power, window, rank)
    same_map = bool(np.array_equal(ours.threshold, alpha * reference_map))
    same_mask = bool(np.array_equal(ours.mask, power > alpha * reference_map))
    t = interleaved(
        {
            "map": lambda: cfar_2d(power, method="os", guard=GUARD, train=TRAIN, pfa=PFA).threshold,
            "mask": lambda: cfar_2d(power, method="os", guard=GUARD, train=TRAIN, pfa=PFA).mask,
            "scipy": lambda: alpha * os_statistic_map(power, window, rank),
        },
        max(3, repeat // 6),
    )
    rows.append(("OS-CFAR 512x256 full threshold map", t["map"], "scipy.ndimage.rank_filter map", t["scipy"],
                 f"maps identical: {same_map}"))
    rows.append(("OS-CFAR 512x256 detection mask only", t["mask"], "scipy.ndimage.rank_filter map", t["scipy"],
                 f"different output (mask, no map); masks identical: {same_mask}"))
    rows.append(("", t["mask"], "strawman: per-cell Python loop", strawman_cfar_per_cell(power, "os", window),
                 "labelled strawman, extrapolated"))
    return rows + openradar_rows(power, repeat)


# --- 1-D CFAR against OpenRadar ----------------------------------------------------------


def ring_1d(guard: int, train: int) -> np.ndarray:
    footprint = np.ones(2 * (guard + train) + 1, dtype=bool)
    footprint[train : train + 2 * guard + 1] = False
    return footprint


def openradar_os_map(power_t: np.ndarray, guard: int, train: int, rank: int) -> np.ndarray:
    """OpenRadar's ``os_`` (1-D only: one call per Doppler column), rank 1-based."""
    return np.stack([openradar_cfar.os_(col, guard_len=guard, noise_len=train, k=rank - 1)[1] for col in power_t])


def openradar_rows(power: np.ndarray, repeat: int) -> list[Row]:
    if openradar_cfar is None:
        missing_peer("openradar", "1-D CA- and OS-CFAR against OpenRadar")
        return []
    rows: list[Row] = []
    guard, train = (GUARD_1D, 0), (TRAIN_1D, 0)
    window = CfarWindow(*guard, *train)
    power_t = np.ascontiguousarray(power.T)  # OpenRadar filters along the last axis: [D, R]

    # CA, circular edges on both sides; OpenRadar's threshold is noise + l_bound (log
    # maps), so the linear-power decision multiplies its noise floor by the package's alpha.
    alpha = cfar_alpha("ca", window.n_train, PFA)

    def openradar_ca() -> np.ndarray:
        noise = openradar_cfar.ca_(power_t, guard_len=GUARD_1D, noise_len=TRAIN_1D, mode="wrap", l_bound=0)[1]
        return power_t > alpha * noise

    ours = cfar_2d(power, method="ca", guard=guard, train=train, pfa=PFA, edge="wrap")
    theirs = openradar_ca().T
    t = interleaved(
        {
            "ours": lambda: cfar_2d(power, method="ca", guard=guard, train=train, pfa=PFA, edge="wrap"),
            "theirs": openradar_ca,
        },
        repeat,
    )
    rows.append((f"1-D CA-CFAR along range, {window.n_train} cells", t["ours"], "OpenRadar ca_ (convolve1d)",
                 t["theirs"], f"{int(ours.mask.sum())} detections, {int((ours.mask != theirs).sum())} differ"))

    # OS: guard cells > 0, compared with an independent scipy rank_filter reference.
    rank = default_os_rank(window.n_train)
    alpha = cfar_alpha("os", window.n_train, PFA)
    reference = power_t > alpha * scipy.ndimage.rank_filter(
        power_t, rank - 1, footprint=ring_1d(GUARD_1D, TRAIN_1D)[None, :], mode="wrap"
    )
    ours = cfar_2d(power, method="os", guard=guard, train=train, pfa=PFA, edge="wrap").mask.T
    theirs = power_t > alpha * openradar_os_map(power_t, GUARD_1D, TRAIN_1D, rank)
    t_ours = time_calls(lambda: cfar_2d(power, method="os", guard=guard, train=train, pfa=PFA, edge="wrap"), repeat)
    t_theirs = time_calls(lambda: openradar_os_map(power_t, GUARD_1D, TRAIN_1D, rank), 3)
    rows.append((f"1-D OS-CFAR along range, guard {GUARD_1D}", t_ours, "OpenRadar os_ (Python loop per cell)",
                 t_theirs, f"vs scipy reference ({int(reference.sum())} det.): package {int((ours != reference).sum())}"
                 f" differ, OpenRadar {int((theirs != reference).sum())} differ"))
    # Without guard cells OpenRadar's window is right: the detections agree.
    zero = CfarWindow(0, 0, TRAIN_1D, 0)
    rank0 = default_os_rank(zero.n_train)
    alpha0 = cfar_alpha("os", zero.n_train, PFA)
    ours0 = cfar_2d(power, method="os", guard=(0, 0), train=train, pfa=PFA, edge="wrap").mask.T
    theirs0 = power_t > alpha0 * openradar_os_map(power_t, 0, TRAIN_1D, rank0)
    rows.append(("1-D OS-CFAR along range, guard 0", t_ours, "OpenRadar os_", None,
                 f"{int(ours0.sum())} detections, {int((ours0 != theirs0).sum())} differ"))
    return rows


# --- DOA ---------------------------------------------------------------------------------------


def plain_bartlett(snapshots: np.ndarray, steer: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """Vectorised Bartlett: one matrix product over every detection and a 0.1-degree grid."""
    return grid[np.argmax(np.abs(snapshots @ steer.conj().T), axis=1)]


def doa_rows(rng: np.random.Generator, repeat: int) -> list[Row]:
    wavelength = SPEED_OF_LIGHT_MPS / 77e9
    rx = np.c_[np.zeros(4), np.arange(4) * wavelength / 2, np.zeros(4)]
    truth = np.deg2rad(rng.uniform(-60, 60, 100))
    snaps = steering_vectors(truth, rx, wavelength) + 0.1 * (rng.standard_normal((100, 4)) + 1j * rng.standard_normal((100, 4)))
    grid = np.deg2rad(np.arange(-90, 90.05, 0.1))
    steer = steering_vectors(grid, rx, wavelength)
    rms = lambda est: np.rad2deg(np.sqrt(np.mean((est - truth) ** 2)))  # noqa: E731
    fns = {m: (lambda m=m: estimate_azimuth(snaps, rx, wavelength, method=m)) for m in ("bartlett", "capon", "music")}
    fns["plain"] = lambda: plain_bartlett(snaps, steer, grid)
    t = interleaved(fns, repeat)
    plain_rms = rms(fns["plain"]())
    return [
        (f"DOA {m}, 100 detections", t[m], "plain vectorised Bartlett, 0.1 deg grid", t["plain"],
         f"RMS error {rms(fns[m]()):.2f} deg (plain {plain_rms:.2f} deg)")
        for m in ("bartlett", "capon", "music")
    ]


# --- runs --------------------------------------------------------------------------------------


def cuda_rows(batch: int, repeat: int) -> list[Row]:
    import torch

    from zendar_dataset.radar.batched_chain import RadarChain

    if not torch.cuda.is_available():
        print("--device cuda: no CUDA device here; the batched chain was not measured.")
        return []
    wavelength = SPEED_OF_LIGHT_MPS / 77e9
    params = FmcwParams(77e9, 853e6, 20e6, 512, 256, 30e-6, np.c_[np.zeros(4), np.arange(4) * wavelength / 2, np.zeros(4)])
    frames = torch.randn(batch, 256, 512, 4, dtype=torch.complex64, device="cuda")
    rows: list[Row] = []
    for method in ("ca", "os"):
        chain = RadarChain(params, device="cuda", cfar={"method": method})

        def run() -> None:
            chain.from_raw(frames)
            torch.cuda.synchronize()

        ours = time_calls(run, repeat)
        rows.append((f"chain {method.upper()} + Bartlett, batch {batch}", ours, "-", None,
                     f"{batch / ours.median:,.0f} frames/s"))
    return rows


CPU_ROWS = {"range-doppler": range_doppler_rows, "cfar": cfar_rows, "doa": doa_rows}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=30)
    parser.add_argument("--device", choices=("cpu", "cuda"), default="cpu")
    parser.add_argument("--batch", type=int, default=64)
    parser.add_argument("--only", choices=sorted(CPU_ROWS), help="one group of CPU rows (default: all)")
    args = parser.parse_args()
    print_environment(("numpy", "scipy", "numba", "openradar"))
    rng = np.random.default_rng(0)
    if args.device == "cuda":
        rows = cuda_rows(args.batch, args.repeat)
    else:
        groups = [args.only] if args.only else list(CPU_ROWS)
        rows = [row for group in groups for row in CPU_ROWS[group](rng, args.repeat)]
    # numpy and scipy may each load a BLAS of their own, with the same thread count.
    blas = max((pool["num_threads"] for pool in threadpoolctl.threadpool_info() if pool["user_api"] == "blas"), default=1)
    print(f"threads: range-Doppler, package and plain scipy.fft, workers=-1 ({os.cpu_count()}); CFAR: package "
          f"serial numba, numpy / scipy.ndimage / OpenRadar 1; DOA: numpy with {blas} BLAS thread(s) on both sides")
    print("times: median (min-max) ms over repeated calls; ratio = reference median / package median")
    print(f"{'case':<44} {'package ms':>22} {'reference':<42} {'ref ms':>24} {'ratio':>7}  note")
    for name, ours, ref_name, ref, note in rows:
        ours_ms = ours.scaled(1e3)
        ref_text = ref.scaled(1e3).text() if ref is not None else "-"
        ratio = f"{ref.median / ours.median:6.1f}x" if ref is not None else "-"
        print(f"{name:<44} {ours_ms.text():>22} {ref_name:<42} {ref_text:>24} {ratio:>7}  {note}")
    print_load_after()


if __name__ == "__main__":
    main()
