"""The median interval of a stream of timestamps, exactly as ``np.median(np.diff(t))``.

The synchronisation index's default tolerances need every stream's median interval. ``np.median``
selects with a vectorised partition, fast on intervals with capture jitter (0.1 ms for an hour of a
24 Hz camera with AVX2), but slow on a fixed-rate clock such as the 100 Hz tracklog: a few distinct
intervals repeated hundreds of thousands of times (1.9 ms for an hour, the largest part of building
the index; benchmarks/bench_sync.py). Such intervals are counted instead, in one compiled pass over
the timestamps that never materialises the intervals and gives up as soon as an interval falls
outside a small window around the first one; any stream it gives up on goes to ``np.median``.
"""

from __future__ import annotations

import numba
import numpy as np

# Distinct interval values (ns) the counting pass holds: the counts fit in the L1 cache, and a fixed
# clock's intervals (a few ns apart after rounding, a few hundred with timestamping jitter) fit in it.
COUNTED_SPAN_NS = 4096


@numba.njit(cache=True, nogil=True)
def _counted_middle(t: np.ndarray, rank_low: int, rank_high: int, span: int) -> tuple[bool, int, int]:
    """``(counted, low, high)``: the intervals' values at the two ranks, when every interval lies
    within ``span // 2`` of the first one; ``counted`` False (and no values) as soon as one does not."""
    offset = t[1] - t[0] - span // 2
    counts = np.zeros(span, np.int64)
    for i in range(t.size - 1):
        k = t[i + 1] - t[i] - offset
        if k < 0 or k >= span:
            return False, 0, 0
        counts[k] += 1
    low = high = -1
    seen = 0
    for k in range(span):
        seen += counts[k]
        if low < 0 and seen > rank_low:
            low = k
        if seen > rank_high:
            high = k
            break
    return True, offset + low, offset + high


def median_interval_ns(timestamp_ns: np.ndarray) -> int | None:
    """``int(np.median(np.diff(timestamp_ns)))``, or None with fewer than two timestamps.

    Parameters
    ----------
    timestamp_ns : numpy.ndarray
        ``[N]`` int64 timestamps, ns (any order: intervals may be negative).

    Returns
    -------
    int or None
        The median interval in ns: with an even count of intervals, the mean of the two middle ones
        (in float64, as ``np.median``) truncated towards zero.
    """
    t = np.ascontiguousarray(timestamp_ns, dtype=np.int64)
    n = t.size - 1
    if n < 1:
        return None
    counted, low, high = _counted_middle(t, (n - 1) // 2, n // 2, COUNTED_SPAN_NS)
    if not counted:
        return int(np.median(np.diff(t)))
    return int((float(low) + float(high)) / 2)


__all__ = ["COUNTED_SPAN_NS", "median_interval_ns"]
