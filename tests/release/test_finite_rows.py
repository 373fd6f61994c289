"""The lidar's finite-point rule: a point is kept only when finite in both its positions."""

from __future__ import annotations

import numpy as np

from zendar_dataset.release.importer import _finite_rows


def test_every_point_finite_needs_no_mask():
    assert _finite_rows(np.ones((4, 3)), np.zeros((4, 3))) is None
    assert _finite_rows(np.zeros((0, 3)), np.zeros((0, 3))) is None


def test_a_point_not_finite_in_either_position_is_dropped():
    local, ecef = np.ones((5, 3)), np.ones((5, 3))
    local[1, 2] = np.nan
    ecef[3, 0] = np.inf
    ecef[4, 1] = -np.inf
    np.testing.assert_array_equal(_finite_rows(local, ecef), [True, False, True, False, False])
