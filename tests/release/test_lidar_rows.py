"""A decoded lidar sweep as stored: the finite-point rule and the float32 rounding, against numpy's own operations."""

from __future__ import annotations

import numpy as np
import pytest

from zendar_dataset.release.lidar_rows import stored_sweep


def _numpy_rule(local, ecef, intensity):
    """The rule written with numpy, one operation at a time (the import's former code)."""
    keep = np.isfinite(local).all(axis=1) & np.isfinite(ecef).all(axis=1)
    points = np.empty((int(keep.sum()), 4), np.float32)
    with np.errstate(over="ignore"):  # past float32's range the cast gives ±inf, as the rule wants
        points[:, :3] = local[keep]
        points[:, 3] = np.nan_to_num(intensity[keep])
    return points, ecef[keep], int(keep.size - keep.sum())


def _decoded_table(rows: int, seed: int) -> np.ndarray:
    """``[rows, 7]`` float64 like the column decoder's: ECEF x, y, z, local x, y, z, intensity."""
    rng = np.random.default_rng(seed)
    table = np.empty((rows, 7))
    table[:, :3] = rng.normal(size=(rows, 3)) * 30.0 + np.array([-2.7e6, -4.3e6, 3.85e6])
    table[:, 3:6] = rng.normal(size=(rows, 3)) * 40.0
    table[:, 6] = rng.integers(0, 256, rows)
    return table


def test_strided_columns_of_a_decoded_table_match_numpy():
    table = _decoded_table(5000, 0)
    got = stored_sweep(12.5, table[:, 3:6], table[:, :3], table[:, 6])
    points, ecef, dropped = _numpy_rule(table[:, 3:6], table[:, :3], table[:, 6])
    assert got.timestamp_s == 12.5 and got.dropped == dropped == 0
    assert got.points.dtype == np.float32 and got.position_ecef.dtype == np.float64
    assert got.position_ecef.flags.c_contiguous
    np.testing.assert_array_equal(got.points, points)
    np.testing.assert_array_equal(got.position_ecef, ecef)


def test_points_not_finite_in_either_position_are_dropped_and_counted():
    table = _decoded_table(6, 1)
    table[1, 5] = np.nan  # local z
    table[3, 0] = np.inf  # ECEF x
    table[4, 4] = -np.inf  # local y
    got = stored_sweep(0.0, table[:, 3:6], table[:, :3], table[:, 6])
    assert got.dropped == 3
    np.testing.assert_array_equal(got.position_ecef, table[[0, 2, 5], :3])
    np.testing.assert_array_equal(got.points[:, :3], table[[0, 2, 5], 3:6].astype(np.float32))


def test_float32_rounding_overflow_and_intensity_as_numpy_gives_them():
    local = np.array(
        [
            [0.1, -0.0, 1.0 + 2.0**-30],  # rounded to nearest; the sign of zero kept
            [3.4028235677973366e38, 1e39, -1e39],  # the largest float32 kept; past it, ±inf as numpy's cast
            [1e-46, 5e-324, -1e-40],  # below float32's range: 0 and subnormals as numpy rounds them
            [1.0, 2.0, 3.0],
            [4.0, 5.0, 6.0],
        ]
    )
    ecef = np.full((5, 3), 6.4e6)
    intensity = np.array([np.nan, np.inf, -np.inf, 1e300, 254.0])
    got = stored_sweep(1.0, local, ecef, intensity)
    points, _, _ = _numpy_rule(local, ecef, intensity)
    np.testing.assert_array_equal(got.points, points)
    assert np.signbit(got.points[0, 1])
    assert got.points[0, 3] == 0.0 and np.isposinf(got.points[1, 3]) and np.isneginf(got.points[2, 3])


def test_an_empty_sweep_and_a_sweep_with_nothing_finite():
    empty = stored_sweep(2.0, np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))
    assert empty.points.shape == (0, 4) and empty.position_ecef.shape == (0, 3) and empty.dropped == 0
    nothing = stored_sweep(2.0, np.full((3, 3), np.nan), np.zeros((3, 3)), np.zeros(3))
    assert nothing.points.shape == (0, 4) and nothing.dropped == 3


def test_mismatched_shapes_are_refused():
    with pytest.raises(ValueError, match=r"\[P, 3\] positions"):
        stored_sweep(0.0, np.zeros((4, 3)), np.zeros((5, 3)), np.zeros(4))
