"""The static-scene test on hand-made SAR images whose readings follow from the noise statistics.

The image is unit complex Gaussian noise (``E|n|² = 1``; the median magnitude is ``sqrt(ln 2)``)
with bright single pixels. A point on a bright pixel of amplitude ``A`` reads
``20 log10(A / sqrt(ln 2))`` dB; a point on noise reads the largest of the ``n`` pixels of its
window, whose median is ``ln(n / ln 2) / ln 2`` in power over the median pixel's.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.detection.chain_helpers import T0_NS, parked_poses, sar_frame, sar_frames
from zendar_dataset.detection.static_scene import SarTestParams, is_dynamic, nearest_frames, sar_db_at
from zendar_dataset.errors import ZendarError
from zendar_dataset.sar.frames import SAR_SEARCH_RADIUS_M

PIXEL_M = 0.1
WALL_AMPLITUDE = 100.0
WALL_Y_M = 5.0


@pytest.fixture(scope="module")
def scene():
    poses = parked_poses()
    wall = [(x, WALL_Y_M) for x in np.arange(12.0, 28.0, PIXEL_M)]  # a facade along the street
    sar = sar_frames(front=sar_frame(poses, (10.0, -10.0), PIXEL_M, (200, 200), wall, WALL_AMPLITUDE))
    return poses, sar


def _ecef(poses, points_xy):
    points = np.asarray(points_xy, np.float64)
    return poses.ego_to_ecef(np.column_stack([points, np.zeros(len(points))]), T0_NS)


def test_a_wall_reads_bright_a_car_on_noise_reads_the_noise_maximum_and_outside_is_nan(scene):
    poses, sar = scene
    points = _ecef(poses, [(20.0, WALL_Y_M), (20.0, -3.0), (50.0, 0.0)])  # on the wall, a car on the road, beyond the image
    sar_db = sar_db_at(sar, points, T0_NS)
    assert sar_db[0] == pytest.approx(20 * math.log10(WALL_AMPLITUDE / math.sqrt(math.log(2))), abs=0.5)
    k = round(SAR_SEARCH_RADIUS_M / PIXEL_M)
    n = (2 * k + 1) ** 2
    noise_max_db = 10 * math.log10(math.log(n / math.log(2)) / math.log(2))
    assert sar_db[1] == pytest.approx(noise_max_db, abs=3.0)  # one draw of the maximum of n exponentials
    assert np.isnan(sar_db[2])
    dynamic = is_dynamic(sar_db, SarTestParams(threshold_db=20.0))
    assert dynamic.tolist() == [False, True, False]  # outside every image: not confirmed, not dynamic


def test_a_point_within_the_search_radius_of_a_bright_pixel_is_static_and_one_beyond_is_not(scene):
    poses, sar = scene
    k = round(SAR_SEARCH_RADIUS_M / PIXEL_M)
    inside = _ecef(poses, [(20.0, WALL_Y_M - k * PIXEL_M)])
    beyond = _ecef(poses, [(20.0, WALL_Y_M - (k + 2) * PIXEL_M)])
    params = SarTestParams(threshold_db=20.0)
    assert not is_dynamic(sar_db_at(sar, inside, T0_NS), params)[0]
    assert is_dynamic(sar_db_at(sar, beyond, T0_NS), params)[0]


def test_the_brightest_sensor_wins_and_frames_too_far_in_time_are_not_read():
    poses = parked_poses()
    point = (20.0, 0.0)
    dark = sar_frame(poses, (10.0, -10.0), PIXEL_M, (200, 200), [(28.0, 9.0)], WALL_AMPLITUDE, seed=1)
    bright = sar_frame(poses, (10.0, -10.0), PIXEL_M, (200, 200), [point], WALL_AMPLITUDE, seed=2)
    sar = sar_frames(left=dark, right=bright)
    points = _ecef(poses, [point])
    assert sar_db_at(sar, points, T0_NS)[0] == pytest.approx(20 * math.log10(WALL_AMPLITUDE / math.sqrt(math.log(2))), abs=0.5)
    assert nearest_frames(sar, T0_NS + 100_000_000, 150_000_000) == {"left": 0, "right": 0}
    assert nearest_frames(sar, T0_NS + 200_000_000, 150_000_000) == {}
    assert np.isnan(sar_db_at(sar, points, T0_NS + 200_000_000, max_frame_gap_ns=150_000_000)[0])


def test_the_threshold_is_strict_and_nan_is_never_dynamic():
    params = SarTestParams(threshold_db=10.0)
    assert is_dynamic(np.array([9.99, 10.0, 10.01, np.nan, -np.inf]), params).tolist() == [True, False, False, False, True]


def test_bad_settings_and_points_raise_named_errors(scene):
    poses, sar = scene
    with pytest.raises(ZendarError, match="threshold_db"):
        SarTestParams(threshold_db=float("nan"))
    with pytest.raises(ZendarError, match="max_frame_gap_ns"):
        SarTestParams(max_frame_gap_ns=-1)
    with pytest.raises(ZendarError, match=r"points_ecef must be \[N, 3\]"):
        sar_db_at(sar, np.zeros((4, 2)), T0_NS)
