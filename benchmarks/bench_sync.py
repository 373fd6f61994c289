"""Claim: building the synchronisation index of a 1-hour scene with every stream takes < 1 s.

Streams (jittered like real capture): SAR 10 Hz (reference) and a second SAR stream,
radar ~20 Hz x2 (cube windows of 2), camera 24 Hz, lidar 10 Hz, tracklog 100 Hz.

References, in the same run and interleaved call by call:

* plain vectorised numpy: one ``np.searchsorted`` per stream -- the nearest element
  within tolerance for the four nearest-matched streams, the latest element of a filled
  window for the two radar streams -- with no validation; it must give the package's indices;
* strawman (labelled): a per-reference-time Python loop of ``np.searchsorted``.

The package figures include building its per-stream ``StreamTimes`` (which validates every
timestamp: sorted, unique, int64), as the Dataset does per scene, with the default tolerances
(half a median interval: the medians are computed, which the plain code is spared) and with the
tolerances given as the plain code gets them; and without building them (the medians then kept
from an earlier call).
Single-threaded on both sides. Times: min / median / max over ``--repeats`` calls.

Run: python benchmarks/bench_sync.py [--repeats 15]
"""

from __future__ import annotations

import argparse

import numpy as np
from harness import interleaved, print_environment, print_load_after, time_calls

from zendar_dataset.sync import MISSING, StreamTimes, build_sync_table

HOUR_S = 3600
T0_NS = 1_300_000_000_000_000_000


def stream(rate_hz: float, rng: np.random.Generator, jitter_frac: float = 0.05) -> np.ndarray:
    period_ns = 1e9 / rate_hz
    n = int(HOUR_S * rate_hz)
    jitter = rng.uniform(-jitter_frac, jitter_frac, size=n) * period_ns
    return (T0_NS + np.arange(n) * period_ns + jitter).astype(np.int64)


def plain_nearest(reference_ns: np.ndarray, stream_ns: np.ndarray, tolerance_ns: int) -> np.ndarray:
    """Vectorised nearest match: the element before or after each reference time (the earlier on a tie)."""
    after = np.clip(np.searchsorted(stream_ns, reference_ns), 1, stream_ns.size - 1)
    before = after - 1
    pick = np.where(reference_ns - stream_ns[before] <= stream_ns[after] - reference_ns, before, after)
    return np.where(np.abs(stream_ns[pick] - reference_ns) <= tolerance_ns, pick, MISSING)


def plain_latest(reference_ns: np.ndarray, stream_ns: np.ndarray, window: int, tolerance_ns: int) -> np.ndarray:
    """Vectorised latest element at or before each reference time, when a whole window exists."""
    last = np.searchsorted(stream_ns, reference_ns, side="right") - 1
    ok = (last >= window - 1) & (reference_ns - stream_ns[np.clip(last, 0, None)] <= tolerance_ns)
    return np.where(ok, last, MISSING)


def strawman_nearest(reference_ns, stream_ns, tolerance_ns):
    """Strawman: one searchsorted per reference time, in a Python loop."""
    out = np.full(reference_ns.size, MISSING, dtype=np.int64)
    for k, r in enumerate(reference_ns):
        j = int(np.searchsorted(stream_ns, r))
        candidates = [c for c in (j - 1, j) if 0 <= c < stream_ns.size]
        best = min(candidates, key=lambda c: (abs(int(stream_ns[c]) - int(r)), c))
        if abs(int(stream_ns[best]) - int(r)) <= tolerance_ns:
            out[k] = best
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=15)
    args = parser.parse_args()
    print_environment(("numpy", "pandas"))
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
    table = build_sync_table(reference, streams)
    ref_ns = reference.timestamp_ns

    def validate_and_build():
        checked = [StreamTimes(s.name, s.timestamp_ns, s.window) for s in streams]
        return build_sync_table(StreamTimes(reference.name, reference.timestamp_ns), checked)

    given_ms = {name: tolerance / 1e6 for name, tolerance in table.tolerance_ns.items()}

    def validate_and_build_given():
        checked = [StreamTimes(s.name, s.timestamp_ns, s.window) for s in streams]
        return build_sync_table(StreamTimes(reference.name, reference.timestamp_ns), checked, tolerance_ms=given_ms)

    def plain():
        return {
            s.name: (plain_latest(ref_ns, s.timestamp_ns, s.window, table.tolerance_ns[s.name]) if s.window
                     else plain_nearest(ref_ns, s.timestamp_ns, table.tolerance_ns[s.name]))
            for s in streams
        }

    same = plain()
    for s in streams:
        if not np.array_equal(same[s.name][table.reference_index], table.element[s.name]):
            raise AssertionError(f"plain searchsorted and the package disagree on {s.name}")
    times = interleaved(
        {"validate": validate_and_build, "given": validate_and_build_given,
         "build": lambda: build_sync_table(reference, streams), "plain": plain},
        args.repeats,
    )
    nearest = [s for s in streams if not s.window]
    straw = time_calls(
        lambda: [strawman_nearest(ref_ns, s.timestamp_ns, table.tolerance_ns[s.name]) for s in nearest], 1, warmup=0
    )

    print("1-hour scene: " + ", ".join(f"{k} {v}" for k, v in counts.items()))
    print(f"items {len(table)} of {table.n_reference}, dropped {table.dropped_total}; "
          "plain searchsorted gives the package's indices for every stream")
    print(f"{'method':<62}{'ms median (min-max)':>26}{'x package':>11}")
    base = times["validate"].median
    for label, spread in (
        ("package: validate + build_sync_table (7 streams)", times["validate"]),
        ("package: validate + build, tolerances given (the plain's inputs)", times["given"]),
        ("package: build_sync_table only (StreamTimes already built)", times["build"]),
        ("plain numpy: one searchsorted per stream (6 streams)", times["plain"]),
        ("strawman: Python loop of searchsorted (4 nearest streams)", straw),
    ):
        print(f"{label:<62}{spread.scaled(1e3).text():>26}{spread.median / base:>11.2f}")
    print(f"target < 1 s: {'PASS' if times['validate'].median < 1.0 else 'FAIL'}")
    print_load_after()


if __name__ == "__main__":
    main()
