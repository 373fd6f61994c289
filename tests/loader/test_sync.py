import numpy as np
import pandas as pd
import pytest

from zendar_dataset.errors import ZendarFormatError
from zendar_dataset.sync import MISSING, StreamTimes, build_sync_table, resolve_tolerances_ns

MS = 1_000_000
T0 = 1_000_000_000_000_000_000


def reference(n=10, step_ms=100):
    return StreamTimes("sar/left", T0 + step_ms * MS * np.arange(n, dtype=np.int64))


def brute_force_nearest(reference_ns, stream_ns, tolerance_ns):
    """Independent reference: scan every element, keep the earliest of the closest."""
    out = []
    for r in reference_ns:
        best, best_abs = MISSING, None
        for k, s in enumerate(stream_ns):
            d = abs(int(s) - int(r))
            if d <= tolerance_ns and (best_abs is None or d < best_abs):
                best, best_abs = k, d
        out.append(best)
    return np.array(out)


def test_tolerance_is_inclusive_to_the_nanosecond():
    ref = reference(4)
    tol_ns = 7 * MS
    # Elements exactly at +tol, exactly at -tol, 1 ns beyond +tol and 1 ns beyond -tol.
    offsets = np.array([tol_ns, -tol_ns, tol_ns + 1, -tol_ns - 1])
    camera = StreamTimes("camera/front", ref.timestamp_ns + offsets)
    table = build_sync_table(ref, [camera], tolerance_ms=7.0)
    np.testing.assert_array_equal(table.element["camera/front"], [0, 1, MISSING, MISSING])
    np.testing.assert_array_equal(table.dt_ns["camera/front"][:2], [tol_ns, -tol_ns])
    assert table.tolerance_ns["camera/front"] == tol_ns
    assert len(table) == 4  # a missing optional stream does not drop the frame


def test_default_tolerance_half_median_interval_and_edges():
    ref = reference(5, step_ms=100)
    # A 24 Hz-like camera with a 40 ms interval: default tolerance 20 ms.
    camera_ns = T0 - 3 * MS + 40 * MS * np.arange(20, dtype=np.int64)
    lidar_ns = np.array([T0 + 50 * MS, T0 + 150 * MS + 1, T0 + 250 * MS], dtype=np.int64)
    streams = [StreamTimes("camera/front", camera_ns), StreamTimes("lidar/top", lidar_ns)]
    tolerances = resolve_tolerances_ns(streams, None, ref.timestamp_ns)
    assert tolerances == {"camera/front": 20 * MS, "lidar/top": 50 * MS}
    table = build_sync_table(ref, streams)
    # Frame 0 (0 ms): element 0 is +50 ms, exactly the tolerance (kept).
    # Frame 1 (100 ms): element 0 at -50 ms beats element 1 at +50 ms + 1 ns.
    # Frame 2 (200 ms): element 1 at -50 ms + 1 ns beats element 2 at +50 ms.
    # Frame 3 (300 ms): element 2 at -50 ms. Frame 4 (400 ms): nothing within 50 ms.
    np.testing.assert_array_equal(table.element["lidar/top"], [0, 0, 1, 2, MISSING])
    np.testing.assert_array_equal(table.dt_ns["lidar/top"], [50 * MS, -50 * MS, -50 * MS + 1, -50 * MS, 0])
    np.testing.assert_array_equal(
        table.element["camera/front"], brute_force_nearest(ref.timestamp_ns, camera_ns, 20 * MS)
    )


def test_matches_brute_force_on_random_streams():
    rng = np.random.default_rng(5)
    ref_ns = np.sort(rng.choice(10**9, size=200, replace=False)).astype(np.int64)
    stream_ns = np.sort(rng.choice(10**9, size=300, replace=False)).astype(np.int64)
    tol_ns = 2_000_000
    table = build_sync_table(StreamTimes("sar/a", ref_ns), [StreamTimes("camera/c", stream_ns)], tolerance_ms=2.0)
    expected = brute_force_nearest(ref_ns, stream_ns, tol_ns)
    np.testing.assert_array_equal(table.element["camera/c"], expected)
    present = expected != MISSING
    np.testing.assert_array_equal(table.dt_ns["camera/c"][present], stream_ns[expected[present]] - ref_ns[present])


def test_per_stream_tolerance_dict_by_stream_or_group():
    ref = reference(3)
    a = StreamTimes("camera/a", ref.timestamp_ns + 5 * MS)
    b = StreamTimes("camera/b", ref.timestamp_ns + 5 * MS)
    lidar = StreamTimes("lidar/top", ref.timestamp_ns + 5 * MS)
    table = build_sync_table(ref, [a, b, lidar], tolerance_ms={"camera": 4.0, "camera/b": 5.0, "lidar": 6})
    assert table.tolerance_ns == {"camera/a": 4 * MS, "camera/b": 5 * MS, "lidar/top": 6 * MS}
    assert np.all(table.element["camera/a"] == MISSING)
    assert np.all(table.element["camera/b"] == [0, 1, 2])
    with pytest.raises(ValueError, match="not matched by tolerance"):
        build_sync_table(ref, [a], tolerance_ms={"camra": 4.0})
    with pytest.raises(ValueError, match="non-negative"):
        build_sync_table(ref, [a], tolerance_ms=-1.0)
    with pytest.raises(ValueError, match="tolerance_ms"):
        build_sync_table(ref, [a], tolerance_ms="5")


def test_window_takes_latest_at_or_before_and_counts_drops():
    ref = reference(6)  # 0, 100, ..., 500 ms
    # Radar at 50 ms spacing starting at 40 ms: cubes 40, 90, 140, ...
    radar_ns = T0 + 40 * MS + 50 * MS * np.arange(12, dtype=np.int64)
    radar = StreamTimes("radar/left", radar_ns, window=3)
    table = build_sync_table(ref, [radar])
    assert table.tolerance_ns["radar/left"] == 75 * MS
    # Frame 0 (0 ms) has no cube at or before; frame 1 (100 ms) has 2 (40, 90): both dropped.
    assert table.dropped["radar/left"] == 2 and table.dropped_total == 2
    np.testing.assert_array_equal(table.reference_index, [2, 3, 4, 5])
    # 200 ms -> latest cube 190 ms (index 3): window 1..3.
    np.testing.assert_array_equal(table.element["radar/left"], [3, 5, 7, 9])
    np.testing.assert_array_equal(table.dt_ns["radar/left"], [-10 * MS] * 4)
    # A cube exactly at the reference time is "at or before".
    exact = StreamTimes("radar/left", ref.timestamp_ns.copy(), window=1)
    np.testing.assert_array_equal(build_sync_table(ref, [exact]).dt_ns["radar/left"], np.zeros(6))


def test_window_tolerance_edge_and_keep_unfilled():
    ref = reference(2)
    radar = StreamTimes("radar/left", np.array([T0 - 30 * MS, T0 + 100 * MS - 30 * MS - 1]), window=1)
    table = build_sync_table(ref, [radar], tolerance_ms=30.0)
    # Frame 0's latest cube is exactly 30 ms old (kept); frame 1's is 30 ms + 1 ns old (dropped).
    np.testing.assert_array_equal(table.reference_index, [0])
    assert table.dropped["radar/left"] == 1
    kept = build_sync_table(ref, [radar], tolerance_ms=30.0, keep_unfilled_windows=True)
    np.testing.assert_array_equal(kept.element["radar/left"], [0, MISSING])
    assert kept.dropped_total == 0


def test_require_drops_and_counts_per_stream():
    ref = reference(4)
    camera = StreamTimes("camera/front", ref.timestamp_ns[[0, 2]])
    lidar = StreamTimes("lidar/top", ref.timestamp_ns[[0, 1]])
    table = build_sync_table(ref, [camera, lidar], tolerance_ms=10.0, require=["camera", "lidar/top"])
    np.testing.assert_array_equal(table.reference_index, [0])
    assert table.dropped == {"camera/front": 2, "lidar/top": 2}
    assert table.dropped_total == 3
    with pytest.raises(ValueError, match="require names unknown"):
        build_sync_table(ref, [camera], require=["radar"])


def test_frame_and_stats():
    ref = reference(3)
    camera = StreamTimes("camera/front", ref.timestamp_ns[:2] + np.array([3 * MS, -4 * MS]))
    table = build_sync_table(ref, [camera], tolerance_ms=10.0)
    frame = table.to_frame()
    assert list(frame.columns) == ["reference_index", "timestamp_ns", "camera/front:element", "camera/front:dt_ns"]
    assert frame["camera/front:dt_ns"].isna().tolist() == [False, False, True]
    assert frame["camera/front:dt_ns"].iloc[1] == -4 * MS
    stats = table.residual_stats().set_index("stream").loc["camera/front"]
    assert stats["matched"] == 2 and stats["missing"] == 1 and stats["dropped"] == 0
    assert stats["abs_dt_max_ns"] == 4 * MS and stats["abs_dt_median_ns"] == 3.5 * MS
    assert stats["dt_min_ns"] == -4 * MS and stats["tolerance_ms"] == 10.0
    assert isinstance(table.residual_stats(), pd.DataFrame)


def test_bad_timestamps():
    with pytest.raises(ZendarFormatError, match=r"camera/front/timestamp_ns.*strictly increasing.*element 2"):
        StreamTimes("camera/front", np.array([1, 2, 2, 3]))
    with pytest.raises(ZendarFormatError, match="int64"):
        StreamTimes("camera/front", np.array([1.0, 2.0]))


def test_empty_stream_and_single_element_defaults():
    ref = reference(3)
    empty = StreamTimes("camera/front", np.zeros(0, dtype=np.int64))
    single = StreamTimes("lidar/top", ref.timestamp_ns[1:2] + 50 * MS)
    table = build_sync_table(ref, [empty, single])
    assert np.all(table.element["camera/front"] == MISSING)
    # A single element falls back to half the reference interval: 50 ms, inclusive.
    np.testing.assert_array_equal(table.element["lidar/top"], [MISSING, 0, 0])


def test_equidistant_tie_goes_to_the_earlier_element():
    ref = reference(1)
    camera = StreamTimes("camera/front", ref.timestamp_ns[0] + np.array([-5 * MS, 5 * MS]))
    table = build_sync_table(ref, [camera], tolerance_ms=5.0)
    np.testing.assert_array_equal(table.element["camera/front"], [0])
    np.testing.assert_array_equal(table.dt_ns["camera/front"], [-5 * MS])


@pytest.mark.parametrize("n_stream", [1, 2, 7, 400])
def test_nearest_indices_are_those_of_pandas_merge_asof(n_stream):
    """The package finds the nearest element with searchsorted; pandas' merge_asof (nearest, inclusive
    tolerance) is the independent reference: references before, inside and after the stream, exact
    hits and exact ties between two elements."""
    rng = np.random.default_rng(n_stream)
    stream_ns = T0 + np.sort(rng.choice(10_000, size=n_stream, replace=False)).astype(np.int64) * 2 * MS
    ref_ns = np.sort(np.concatenate([
        T0 + rng.integers(-2_000, 22_000, size=300) * MS,  # around and beyond the stream
        stream_ns[: min(5, n_stream)],  # exact hits
        (stream_ns[:-1] + stream_ns[1:])[:5] // 2,  # exact ties (the elements are an even number of ms apart)
    ]))
    left = pd.DataFrame({"timestamp_ns": np.unique(ref_ns)})
    right = pd.DataFrame({"timestamp_ns": stream_ns, "element": np.arange(n_stream)})
    for tolerance_ns in (3 * MS, 100_000 * MS):  # a few matches; every reference matched, ties decided
        table = build_sync_table(StreamTimes("sar/left", np.unique(ref_ns)), [StreamTimes("camera/front", stream_ns)],
                                 tolerance_ms=tolerance_ns / MS)
        merged = pd.merge_asof(left, right, on="timestamp_ns", direction="nearest", tolerance=tolerance_ns)
        expected = merged["element"].fillna(MISSING).to_numpy(np.int64)
        np.testing.assert_array_equal(table.element["camera/front"], expected)
        assert (expected != MISSING).any()


def _median_cases():
    rng = np.random.default_rng(21)
    jittered = (1e7 + rng.uniform(-5e5, 5e5, 360_000)).astype(np.int64)
    yield "100 Hz hour, jittered", jittered
    yield "odd length", jittered[:100_001]
    yield "a fixed-rate clock's two intervals", rng.choice(np.array([9_999_872, 10_000_128]), 360_000)
    yield "few distinct values", rng.integers(-3, 3, 50_000)
    clock = rng.choice(np.array([10_000_000 - 2048, 10_000_000, 10_000_000 + 2047]), 100_000)
    clock[0] = 10_000_000  # the counting window is centred on the first interval: both ends are in it
    yield "a fixed clock at the ends of the counted span", clock
    yield "a fixed clock, its last interval one past the counted span", np.r_[clock[:-1], 10_000_000 + 2048]
    yield "a fixed clock with one gap at the end", np.r_[np.full(99_999, 10_000_000), 20_000_000]
    yield "two plateaus", np.r_[np.zeros(5_000, np.int64), np.full(5_001, 10**12)]
    yield "sorted descending", np.sort(rng.integers(0, 2**40, 20_000))[::-1].copy()
    # Every sampled value (1 in 64) is an outlier: the sample's bracket misses the median.
    misleading = rng.integers(0, 100, 64 * 200)
    misleading[::64] = 10**9
    yield "sample misleads", misleading
    yield "short", rng.integers(0, 10, 11)


@pytest.mark.parametrize("case", list(_median_cases()), ids=lambda case: case[0])
def test_median_interval_equals_numpy_median_of_the_intervals(case):
    from zendar_dataset.sync import median_interval_ns

    _, intervals = case
    timestamps = np.r_[0, np.cumsum(intervals)].astype(np.int64)  # its intervals are exactly the case's
    assert median_interval_ns(timestamps) == int(np.median(intervals))
    assert median_interval_ns(timestamps[:2]) == int(intervals[0])
    assert median_interval_ns(timestamps[:1]) is None
