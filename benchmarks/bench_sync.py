"""Claim: building the synchronisation index of a 1-hour scene with every stream takes < 1 s.

Streams (jittered like real capture): SAR 10 Hz (reference) and a second SAR stream,
radar ~20 Hz x2 (cube windows of 2), camera 24 Hz, lidar 10 Hz, tracklog 100 Hz.
The plain reference is a per-frame ``np.searchsorted`` nearest match written in Python
(what a user writes by hand); both produce the same indices, checked here.

Run: python benchmarks/bench_sync.py
"""

from __future__ import annotations

import time

import numpy as np

from zendar_dataset.sync import MISSING, StreamTimes, build_sync_table

HOUR_S = 3600
T0_NS = 1_300_000_000_000_000_000


def stream(rate_hz: float, rng: np.random.Generator, jitter_frac: float = 0.05) -> np.ndarray:
    period_ns = 1e9 / rate_hz
    n = int(HOUR_S * rate_hz)
    jitter = rng.uniform(-jitter_frac, jitter_frac, size=n) * period_ns
    return (T0_NS + np.arange(n) * period_ns + jitter).astype(np.int64)


def python_nearest(reference_ns, stream_ns, tolerance_ns):
    out = np.full(reference_ns.size, MISSING, dtype=np.int64)
    for k, r in enumerate(reference_ns):
        j = int(np.searchsorted(stream_ns, r))
        candidates = [c for c in (j - 1, j) if 0 <= c < stream_ns.size]
        best = min(candidates, key=lambda c: (abs(int(stream_ns[c]) - int(r)), c))
        if abs(int(stream_ns[best]) - int(r)) <= tolerance_ns:
            out[k] = best
    return out


def main() -> None:
    rng = np.random.default_rng(0)
    reference = StreamTimes("sar/left", stream(10, rng))
    streams = [
        StreamTimes("sar/right", reference.timestamp_ns.copy()),
        StreamTimes("radar/left", stream(20.1, rng), window=2),
        StreamTimes("radar/right", stream(19.9, rng), window=2),
        StreamTimes("camera/front", stream(24, rng)),
        StreamTimes("lidar/top", stream(10, rng)),
        StreamTimes("tracklog", stream(100, rng, 0.0)),
    ]
    counts = {s.name: s.timestamp_ns.size for s in [reference, *streams]}
    build_sync_table(reference, streams)  # warm-up (imports, allocator)
    runs = []
    for _ in range(5):
        start = time.perf_counter()
        # Includes validating every stream's timestamps, as the Dataset does per scene.
        checked = [StreamTimes(s.name, s.timestamp_ns, s.window) for s in streams]
        table = build_sync_table(StreamTimes(reference.name, reference.timestamp_ns), checked)
        runs.append(time.perf_counter() - start)
    index_s = min(runs)

    nearest = [s for s in streams if not s.window]
    start = time.perf_counter()
    plain = {s.name: python_nearest(reference.timestamp_ns, s.timestamp_ns, table.tolerance_ns[s.name]) for s in nearest}
    plain_s = time.perf_counter() - start
    for s in nearest:
        assert np.array_equal(plain[s.name][table.reference_index], table.element[s.name]), s.name

    print("1-hour scene: " + ", ".join(f"{k} {v}" for k, v in counts.items()))
    print(f"{'method':<44}{'seconds':>10}{'ratio':>10}")
    print(f"{'validate + build_sync_table (7 streams)':<44}{index_s:>10.3f}{1.0:>10.2f}")
    print(f"{'python searchsorted loop (4 nearest streams)':<44}{plain_s:>10.3f}{plain_s / index_s:>10.2f}")
    print(f"items {len(table)} of {table.n_reference}, dropped {table.dropped_total}")
    print(f"target < 1 s: {'PASS' if index_s < 1.0 else 'FAIL'}")


if __name__ == "__main__":
    main()
