"""The static-scene test on hand-made SAR images and range-Doppler SNRs that follow the radar equation.

The image is unit complex Gaussian noise (``E|n|² = 1``; the median magnitude is ``sqrt(ln 2)``)
with bright single pixels. A point on a bright pixel of amplitude ``A`` reads
``20 log10(A / sqrt(ln 2))`` dB; a point on noise reads the largest of the ``n`` pixels of its
window, whose median is ``ln(n / ln 2) / ln 2`` in power over the median pixel's. The test's value
is that reading minus the point's range-Doppler SNR.

Physics of the range test: a scatterer of the same RCS returns ``SNR(R) = SNR(10 m) - 40 log10(R /
10 m)`` in the range-Doppler map (radar equation, power ∝ R⁻⁴) and, when static, a SAR pixel of
that power times the aperture's integration gain (the images are not range-compensated); a moving
car's SAR energy is spread over a patch of pixels as speckle.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from tests.detection.chain_helpers import (
    T0_NS,
    LidarReader,
    parked_poses,
    radar_calibration,
    radar_params,
    sar_frame,
    sar_frames,
    simulate_cube,
)
from zendar_dataset.detection.cells import RadarCells, cfar_cells
from zendar_dataset.detection.points import cell_snr_db, cube_points
from zendar_dataset.detection.static_scene import (
    SarTestParams,
    is_dynamic,
    nearest_frames,
    sar_db_at,
)
from zendar_dataset.errors import ZendarError
from zendar_dataset.sar.frames import SAR_SEARCH_RADIUS_M
from zendar_dataset.sar.shadow import RadarShadow

PIXEL_M = 0.1
WALL_AMPLITUDE = 100.0
WALL_Y_M = 5.0
MEDIAN_DB = 10 * math.log10(math.log(2))  # the median pixel's power over the mean noise power, dB
# Range test: a car-sized RCS gives 40 dB at 10 m in the range-Doppler map; the aperture's coherent gain
# over that SNR is 30 dB (what static points read over their SNR on the demo's training split, median
# 31 dB); a mover's energy is smeared over 30 x 30 pixels of 0.25 m.
SNR_AT_10_M_DB = 40.0
SAR_GAIN_DB = 30.0
SMEAR_PIXELS = 30
RANGE_PIXEL_M = 0.25


@pytest.fixture(scope="module")
def scene():
    poses = parked_poses()
    wall = [(x, WALL_Y_M) for x in np.arange(12.0, 28.0, PIXEL_M)]  # a facade along the street
    sar = sar_frames(front=sar_frame(poses, (10.0, -10.0), PIXEL_M, (200, 200), wall, WALL_AMPLITUDE))
    return poses, sar


def _ecef(poses, points_xy):
    points = np.asarray(points_xy, np.float64)
    return poses.ego_to_ecef(np.column_stack([points, np.zeros(len(points))]), T0_NS)


def _snr_db(range_m: float) -> float:
    return SNR_AT_10_M_DB - 40.0 * math.log10(range_m / 10.0)


def test_the_value_is_the_sar_reading_minus_the_snr_and_outside_is_nan(scene):
    poses, sar = scene
    points = _ecef(poses, [(20.0, WALL_Y_M), (20.0, -3.0), (50.0, 0.0)])  # on the wall, a car on the road, beyond the image
    reading_db = sar_db_at(sar, points, T0_NS, rd_snr_db=np.zeros(3))
    assert reading_db[0] == pytest.approx(20 * math.log10(WALL_AMPLITUDE) - MEDIAN_DB, abs=0.5)
    k = round(SAR_SEARCH_RADIUS_M / PIXEL_M)
    n = (2 * k + 1) ** 2
    noise_max_db = 10 * math.log10(math.log(n / math.log(2)) / math.log(2))
    assert reading_db[1] == pytest.approx(noise_max_db, abs=3.0)  # one draw of the maximum of n exponentials
    assert np.isnan(reading_db[2])
    snr_db = np.array([12.0, -4.0, 30.0])
    np.testing.assert_allclose(sar_db_at(sar, points, T0_NS, rd_snr_db=snr_db), reading_db - snr_db)


def test_a_static_scatterer_reads_static_and_a_mover_dynamic_at_8_m_and_at_45_m_where_no_absolute_level_can():
    """Same RCS, R⁻⁴ falloff: the value is the same at both ranges; the reading alone orders a far static
    point below a near mover."""
    poses = parked_poses()
    rng = np.random.default_rng(7)
    frame = sar_frame(poses, (4.0, -20.0), RANGE_PIXEL_M, (200, 160), [], 0.0, seed=3)  # x 4-54 m, y -20-20 m
    image = frame["image"][0]
    static_xy, moving_xy = [(8.0, 6.0), (45.0, -6.0)], [(8.0, -6.0), (45.0, 6.0)]

    def pixel(x, y):
        return round((x - 4.0) / RANGE_PIXEL_M), round((y + 20.0) / RANGE_PIXEL_M)

    for x, y in static_xy:
        image[pixel(x, y)] = math.sqrt(10 ** ((_snr_db(math.hypot(x, y)) + SAR_GAIN_DB) / 10))
    for x, y in moving_xy:  # the same energy spread over SMEAR_PIXELS² pixels, as speckle
        i, j = pixel(x, y)
        power = 10 ** ((_snr_db(math.hypot(x, y)) + SAR_GAIN_DB) / 10) / SMEAR_PIXELS**2
        patch = (rng.standard_normal((SMEAR_PIXELS, SMEAR_PIXELS)) + 1j * rng.standard_normal((SMEAR_PIXELS, SMEAR_PIXELS))) / math.sqrt(2)
        half = SMEAR_PIXELS // 2
        image[i - half:i + half, j - half:j + half] += (math.sqrt(power) * patch).astype(np.complex64)
    sar = sar_frames(front=frame)
    xy = static_xy + moving_xy
    points = _ecef(poses, xy)
    snr_db = np.array([_snr_db(math.hypot(x, y)) for x, y in xy])

    values = sar_db_at(sar, points, T0_NS, rd_snr_db=snr_db)
    # A static scatterer reads the aperture's gain over the median at any range.
    np.testing.assert_allclose(values[:2], SAR_GAIN_DB - MEDIAN_DB, atol=1.0)
    # A threshold halfway (in dB) between a focused and a smeared scatterer's level holds at every range.
    params = SarTestParams(threshold_db=SAR_GAIN_DB - 10 * math.log10(SMEAR_PIXELS**2) / 2)
    assert is_dynamic(values, params).tolist() == [False, False, True, True]
    # The SAR reading alone: the near mover is brighter than the far static scatterer, so one threshold
    # on it calls the near mover static or the far scatterer dynamic.
    reading_db = sar_db_at(sar, points, T0_NS, rd_snr_db=np.zeros(4))
    assert reading_db[2] > reading_db[1]


def test_a_point_at_the_image_edge_reads_the_clipped_window_and_one_off_the_image_is_nan():
    poses = parked_poses()
    corner = (10.0, -10.0)
    sar = sar_frames(front=sar_frame(poses, corner, PIXEL_M, (50, 50), [corner], WALL_AMPLITUDE))
    points = _ecef(poses, [corner, (corner[0] - 0.6 * PIXEL_M, corner[1])])
    values = sar_db_at(sar, points, T0_NS, rd_snr_db=np.array([20.0, 20.0]))
    assert values[0] == pytest.approx(20 * math.log10(WALL_AMPLITUDE) - MEDIAN_DB - 20.0, abs=0.5)
    assert np.isnan(values[1])


def test_points_without_a_finite_snr_read_nan_and_no_points_read_nothing(scene):
    poses, sar = scene
    points = _ecef(poses, [(20.0, WALL_Y_M)] * 3)
    values = sar_db_at(sar, points, T0_NS, rd_snr_db=np.array([np.nan, np.inf, -np.inf]))
    assert np.isnan(values).all() and not is_dynamic(values).any()
    assert sar_db_at(sar, np.zeros((0, 3)), T0_NS, rd_snr_db=np.zeros(0)).shape == (0,)


def test_a_point_within_the_search_radius_of_a_bright_pixel_is_static_and_one_beyond_is_not(scene):
    poses, sar = scene
    k = round(SAR_SEARCH_RADIUS_M / PIXEL_M)
    inside = _ecef(poses, [(20.0, WALL_Y_M - k * PIXEL_M)])
    beyond = _ecef(poses, [(20.0, WALL_Y_M - (k + 2) * PIXEL_M)])
    params = SarTestParams(threshold_db=10.0)
    snr_db = np.array([10.0])  # the wall reads 40 dB over the median
    assert not is_dynamic(sar_db_at(sar, inside, T0_NS, rd_snr_db=snr_db), params)[0]
    assert is_dynamic(sar_db_at(sar, beyond, T0_NS, rd_snr_db=snr_db), params)[0]


@pytest.mark.parametrize("radius_m", [0.0, 0.2, 0.5])
def test_the_search_radius_decides_how_far_from_a_bright_pixel_a_point_still_reads_it(scene, radius_m):
    poses, sar = scene
    k = round(radius_m / PIXEL_M)
    offsets_m = np.arange(0, 8) * PIXEL_M  # 0-0.7 m off the wall, in whole pixels
    points = _ecef(poses, [(20.0, WALL_Y_M - d) for d in offsets_m])
    values = sar_db_at(sar, points, T0_NS, rd_snr_db=np.full(len(offsets_m), 10.0), search_radius_m=radius_m)
    params = SarTestParams(threshold_db=10.0, search_radius_m=radius_m)
    assert is_dynamic(values, params).tolist() == [i > k for i in range(len(offsets_m))]


def test_search_radius_must_be_a_finite_non_negative_number_of_metres():
    assert SarTestParams().search_radius_m == SAR_SEARCH_RADIUS_M
    assert SarTestParams().to_json()["search_radius_m"] == SAR_SEARCH_RADIUS_M
    for bad in (-0.1, float("nan"), float("inf"), True, "0.2"):
        with pytest.raises(ZendarError, match="search_radius_m"):
            SarTestParams(search_radius_m=bad)


def test_the_brightest_sensor_wins_and_frames_too_far_in_time_are_not_read():
    poses = parked_poses()
    point = (20.0, 0.0)
    dark = sar_frame(poses, (10.0, -10.0), PIXEL_M, (200, 200), [(28.0, 9.0)], WALL_AMPLITUDE, seed=1)
    bright = sar_frame(poses, (10.0, -10.0), PIXEL_M, (200, 200), [point], WALL_AMPLITUDE, seed=2)
    sar = sar_frames(left=dark, right=bright)
    points = _ecef(poses, [point])
    zero = np.zeros(1)
    assert sar_db_at(sar, points, T0_NS, rd_snr_db=zero)[0] == pytest.approx(20 * math.log10(WALL_AMPLITUDE) - MEDIAN_DB, abs=0.5)
    assert nearest_frames(sar, T0_NS + 100_000_000, 150_000_000) == {"left": 0, "right": 0}
    assert nearest_frames(sar, T0_NS + 200_000_000, 150_000_000) == {}
    assert np.isnan(sar_db_at(sar, points, T0_NS + 200_000_000, rd_snr_db=zero, max_frame_gap_ns=150_000_000)[0])


def test_a_point_in_the_radars_shadow_behind_a_lidar_obstacle_reads_nan_unless_the_shadow_is_off(scene):
    """The facade of the fixture's image, also seen by a lidar on the ego: a point behind it (a
    multipath ghost's place) reads NaN, hence not dynamic, with the shadow on; the same point without
    the shadow, and a point on the road before it, keep their values."""
    poses, sar = scene
    lidar_ego = np.array([0.0, 0.0, 1.9])
    wall_x = np.arange(10.0, 30.0, 0.05)
    facade = np.column_stack([wall_x, np.full(wall_x.size, WALL_Y_M), np.full(wall_x.size, 1.0)]) - lidar_ego
    shadowed = sar_frames(**sar._reader.frames)  # the same images, on a scene with a lidar
    shadowed.__dict__["shadow"] = RadarShadow(LidarReader(facade, lidar_ego))
    radar_ecef = _ecef(poses, [(0.0, 0.0)])[0]
    points = _ecef(poses, [(20.0, WALL_Y_M + 4.0), (20.0, -3.0)])  # behind the facade (9.7 m along the ray), on the road
    snr_db = np.array([10.0, 10.0])
    margin_m = SarTestParams().shadow_margin_m
    with_shadow = sar_db_at(shadowed, points, T0_NS, rd_snr_db=snr_db, radar_ecef=radar_ecef, shadow_margin_m=margin_m)
    without = sar_db_at(shadowed, points, T0_NS, rd_snr_db=snr_db, radar_ecef=radar_ecef, shadow_margin_m=None)
    assert np.isnan(with_shadow[0]) and np.isfinite(without).all() and with_shadow[1] == without[1]
    assert is_dynamic(without, SarTestParams())[0] and not is_dynamic(with_shadow, SarTestParams())[0]
    # No radar position, or a scene without lidar: nothing is in a shadow.
    np.testing.assert_array_equal(sar_db_at(shadowed, points, T0_NS, rd_snr_db=snr_db, shadow_margin_m=margin_m), without)
    np.testing.assert_array_equal(sar_db_at(sar, points, T0_NS, rd_snr_db=snr_db, radar_ecef=radar_ecef, shadow_margin_m=margin_m), without)


def test_the_threshold_is_strict_and_nan_is_never_dynamic():
    params = SarTestParams(threshold_db=10.0)
    assert is_dynamic(np.array([9.99, 10.0, 10.01, np.nan, -np.inf]), params).tolist() == [True, False, False, False, True]


def test_a_cells_snr_is_its_power_over_the_training_cells_mean():
    """A uniform power map with one cell 100 times brighter: 20 dB there, 0 dB far from it."""
    n_range, n_doppler, n_antennas = 64, 32, 4
    amplitude = np.full((n_range, n_doppler, n_antennas), 1.0 / math.sqrt(n_antennas), np.complex64)  # power 1 per cell
    amplitude[30, 16] *= 10.0
    cells = RadarCells(np.array([30, 5]), np.array([16, 3]), np.array([0.5, 0.5]))
    np.testing.assert_allclose(cell_snr_db(amplitude, cells), [20.0, 0.0], atol=1e-5)
    assert cell_snr_db(amplitude, RadarCells(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0))).shape == (0,)


def _point_target_on_a_bright_pixel():
    """A point target at 18 m seen by a parked radar, and a SAR image with one bright pixel where the
    chain places the target's strongest cell: ``(cube, cells, strongest, calibration, poses, sar)``."""
    params = radar_params(n_samples=128)
    calibration = radar_calibration(params, 0.0, (0.0, 0.0, 0.0))
    cube = simulate_cube(params, np.array([[18.0, 0.0, 0.0]]), np.zeros((1, 3)), [1.0], noise=1e-2)
    cells = cfar_cells(cube)
    strongest = int(np.argmax(cells.score))
    poses = parked_poses()
    bright_xy = tuple(cube_points(cube, cells, T0_NS, calibration, poses, sar_frames()).points_ego[strongest, :2])
    sar = sar_frames(front=sar_frame(poses, (10.0, -10.0), PIXEL_M, (200, 200), [bright_xy], WALL_AMPLITUDE))
    return cube, cells, strongest, calibration, poses, sar


def test_cube_points_subtract_each_cells_own_snr_from_its_sar_reading():
    cube, cells, strongest, calibration, poses, sar = _point_target_on_a_bright_pixel()
    points = cube_points(cube, cells, T0_NS, calibration, poses, sar)
    expected = 20 * math.log10(WALL_AMPLITUDE) - MEDIAN_DB - 10 * math.log10(cells.score[strongest])
    assert points.sar_db[strongest] == pytest.approx(expected, abs=0.5)


def test_cube_points_read_the_sar_image_within_the_chains_search_radius():
    """The bright pixel moved 0.4 m off the target: the default 0.2 m window misses it, a 0.5 m window
    (the chain's setting) reads it."""
    from zendar_dataset.detection import ChainParams

    cube, cells, strongest, calibration, poses, _ = _point_target_on_a_bright_pixel()
    x, y = cube_points(cube, cells, T0_NS, calibration, poses, sar_frames()).points_ego[strongest, :2]
    sar = sar_frames(front=sar_frame(poses, (10.0, -10.0), PIXEL_M, (200, 200), [(x, y + 0.4)], WALL_AMPLITUDE))
    near = cube_points(cube, cells, T0_NS, calibration, poses, sar)
    wide = cube_points(cube, cells, T0_NS, calibration, poses, sar, ChainParams(sar=SarTestParams(search_radius_m=0.5)))
    expected = 20 * math.log10(WALL_AMPLITUDE) - MEDIAN_DB - 10 * math.log10(cells.score[strongest])
    assert wide.sar_db[strongest] == pytest.approx(expected, abs=0.5)
    assert near.sar_db[strongest] < expected - 20.0


def test_without_the_snr_subtraction_a_point_reads_its_sar_reading_alone():
    """The ablation's test (``subtract_rd_snr=False``): the same point reads its SNR higher, and the
    chain's parameters say which value they were fitted on."""
    from zendar_dataset.detection import ChainParams

    cube, cells, strongest, calibration, poses, sar = _point_target_on_a_bright_pixel()
    reading_alone = ChainParams(sar=SarTestParams(subtract_rd_snr=False))
    subtracted = cube_points(cube, cells, T0_NS, calibration, poses, sar)
    alone = cube_points(cube, cells, T0_NS, calibration, poses, sar, reading_alone)
    assert alone.sar_db[strongest] == pytest.approx(20 * math.log10(WALL_AMPLITUDE) - MEDIAN_DB, abs=0.5)
    finite = np.isfinite(subtracted.sar_db)
    np.testing.assert_allclose(alone.sar_db[finite] - subtracted.sar_db[finite], cell_snr_db(cube, cells)[finite])
    assert reading_alone.to_json()["sar"]["value"] == "SAR reading"
    assert ChainParams().to_json()["sar"]["value"] == "SAR reading minus range-Doppler SNR"


def test_bad_settings_and_points_raise_named_errors(scene):
    _, sar = scene
    with pytest.raises(ZendarError, match="threshold_db"):
        SarTestParams(threshold_db=float("nan"))
    with pytest.raises(ZendarError, match="max_frame_gap_ns"):
        SarTestParams(max_frame_gap_ns=-1)
    for margin in (-1.0, float("inf"), True, "5"):
        with pytest.raises(ZendarError, match="shadow_margin_m"):
            SarTestParams(shadow_margin_m=margin)
    with pytest.raises(ZendarError, match=r"points_ecef must be \[N, 3\]"):
        sar_db_at(sar, np.zeros((4, 2)), T0_NS, rd_snr_db=np.zeros(4))
    with pytest.raises(ZendarError, match=r"rd_snr_db must be \[N\] with N = 4"):
        sar_db_at(sar, np.zeros((4, 3)), T0_NS, rd_snr_db=np.zeros(3))


def test_cfar_cells_carry_the_snr_the_cube_gives():
    rng = np.random.default_rng(3)
    cube = (rng.normal(size=(64, 32, 4)) + 1j * rng.normal(size=(64, 32, 4))).astype(np.complex64)
    cube[20, 5] *= 40.0
    cube[41, 30] *= 25.0
    cells = cfar_cells(cube)
    assert len(cells) >= 2 and cells.snr_db is not None
    from_cube = cell_snr_db(cube, dataclasses.replace(cells, snr_db=None))
    np.testing.assert_allclose(cell_snr_db(cube, cells), from_cube, rtol=1e-12)
    np.testing.assert_allclose(cells.snr_db, 10.0 * np.log10(cells.score), rtol=1e-12)
