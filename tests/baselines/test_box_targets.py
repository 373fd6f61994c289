"""Box targets: labelled boxes projected into a radar's range-Doppler map, checked by hand and against
the exact beat signal of point scatterers on the box."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import gamma

from tests.detection.chain_helpers import T0_NS, driving_poses, parked_poses, radar_calibration, radar_params, simulate_cube
from zendar_baselines.bench.steps import mask_parameters
from zendar_baselines.labels.box_targets import box_footprints
from zendar_baselines.labels.mask_classes import BACKGROUND, MOVING, UNCERTAIN
from zendar_baselines.labels.masks import (
    DEFAULT_FLOOR_MARGIN_DB,
    MaskParams,
    _power_db_and_floor,
    box_label_mask,
    cfar_peak_label_mask,
    label_mask,
)
from zendar_dataset.detection.boxes import LabelBoxes
from zendar_dataset.errors import ZendarError
from zendar_dataset.radar.range_doppler import range_doppler

# 128 range bins of 0.18737 m (24 m reach), 32 Doppler bins of 3.0417 m/s (chain_helpers.radar_params).
PARAMS = radar_params(n_samples=128, n_chirps=32)
RANGE_BIN_M = PARAMS.range_bin_m
DOPPLER_BIN_MPS = PARAMS.doppler_bin_mps
CUBE_NS = T0_NS + 1_000_000_000  # a second into the poses: the radar's velocity is a central difference


def _boxes(x, y, length, width, yaw, vx, vy) -> LabelBoxes:
    return LabelBoxes(CUBE_NS, *(np.atleast_1d(np.asarray(v, np.float64)) for v in (x, y, length, width, yaw, vx, vy)))


def _cells(mask: np.ndarray) -> set[tuple[int, int]]:
    return {(int(r), int(d)) for r, d in zip(*np.nonzero(mask))}


def _within(footprint: np.ndarray, bins: int) -> set[tuple[int, int]]:
    """Cells at most ``bins`` range and Doppler bins from a footprint cell (Doppler modulo D)."""
    steps = range(-bins, bins + 1)
    return {(r + i, (d + j) % footprint.shape[1]) for r, d in _cells(footprint) for i in steps for j in steps}


def test_a_car_ahead_covers_its_range_extent_at_its_doppler_bin():
    # Radar at the ego origin looking along x; the ego parked; a 4 m x 2 m car centred 20 m ahead,
    # driving away at 2 Doppler bins. Nearest point (18, 0): 18 / 0.18737 = 96.07 -> bin 96; farthest
    # (22, +-1): 22.0227 / 0.18737 = 117.54 -> bin 118. Radial speed 2 bins x cos(azimuth): at the
    # widest azimuth, (18, 1), 2 x 18 / sqrt(325) = 1.997 bins -> every point in bin 16 + 2 = 18.
    calibration = radar_calibration(PARAMS, 0.0, (0.0, 0.0, 0.0))
    boxes = _boxes(20.0, 0.0, 4.0, 2.0, 0.0, 2 * DOPPLER_BIN_MPS, 0.0)
    footprints = box_footprints(boxes, calibration, parked_poses(), CUBE_NS, 128, 32)
    assert footprints.in_fov.shape == (1, 128, 32)
    assert _cells(footprints.in_fov[0]) == {(r, 18) for r in range(96, 119)}
    assert not footprints.outside_fov.any()


def test_an_oncoming_car_seen_from_a_driving_ego_wraps_around_the_doppler_axis():
    # The ego drives at 20 m/s; the car comes at 20 m/s - 17 bins, so it closes at 17 bins: bin
    # 16 - 17 = -1, i.e. 31 modulo 32 (the widest azimuth gives 16.97 bins, still 17).
    calibration = radar_calibration(PARAMS, 0.0, (0.0, 0.0, 0.0))
    boxes = _boxes(20.0, 0.0, 4.0, 2.0, 0.0, 20.0 - 17 * DOPPLER_BIN_MPS, 0.0)
    footprints = box_footprints(boxes, calibration, driving_poses(20.0, 0.0), CUBE_NS, 128, 32)
    assert _cells(footprints.in_fov[0]) == {(r, 31) for r in range(96, 119)}


def test_a_side_radar_on_a_turning_ego_sees_the_yaw_rate_at_its_mount():
    # Ego: along ECEF x at 10 m/s while turning at 0.3 rad/s (chain_helpers.driving_poses). At 1 s its
    # heading is 0.3 rad, so in its own axes it moves at (10 cos 0.3, -10 sin 0.3); the mount at
    # (3.5, 0.8) adds omega x r = (-0.3 * 0.8, 0.3 * 3.5). The radar looks left (yaw +90 deg), with
    # 128 Doppler bins of 0.7604 m/s. A small box (5 cm) 12 m to its left drives away along ego y at
    # 5 m/s: range rate 5 - v_mount_y = 5 - (-2.955 + 1.05) = 6.905 m/s = 9.08 bins -> bin 64 + 9.
    # Without the yaw rate's share it would read 7.955 m/s = 10.46 bins -> bin 74.
    params = radar_params(n_samples=128, n_chirps=128)
    speed_mps, yaw_rate, mount = 10.0, 0.3, (3.5, 0.8)
    v_mount_y = -speed_mps * math.sin(0.3) + yaw_rate * mount[0]
    assert round((5.0 - v_mount_y) / params.doppler_bin_mps) == 9
    assert round((5.0 + speed_mps * math.sin(0.3)) / params.doppler_bin_mps) == 10
    calibration = radar_calibration(params, math.pi / 2, (*mount, 0.5))
    boxes = _boxes(mount[0], mount[1] + 12.0, 0.05, 0.05, 0.0, 0.0, 5.0)
    footprints = box_footprints(boxes, calibration, driving_poses(speed_mps, yaw_rate), CUBE_NS, 128, 128)
    # 12 m / 0.18737 = 64.04 -> range bin 64.
    assert _cells(footprints.in_fov[0]) == {(64, 73)}


def test_cars_beyond_the_maximum_range_behind_the_radar_or_outside_its_view_project_nothing():
    calibration = {**radar_calibration(PARAMS, 0.0, (0.0, 0.0, 0.0)), "fov_azimuth_deg": 120.0}
    poses = parked_poses()
    beyond = box_footprints(_boxes(30.0, 0.0, 4.0, 2.0, 0.0, 3.0, 0.0), calibration, poses, CUBE_NS, 128, 32)
    behind = box_footprints(_boxes(-10.0, 0.0, 4.0, 2.0, 0.0, 3.0, 0.0), calibration, poses, CUBE_NS, 128, 32)
    assert not beyond.in_fov.any() and not beyond.outside_fov.any()
    assert not behind.in_fov.any() and not behind.outside_fov.any()
    # Straddling the last range bin (127 = 23.8 m): only the bins from 21 m / 0.18737 = 112.08 on.
    straddling = box_footprints(_boxes(23.0, 0.0, 4.0, 2.0, 0.0, 0.0, 0.0), calibration, poses, CUBE_NS, 128, 32)
    assert set(np.nonzero(straddling.in_fov[0].any(axis=1))[0].tolist()) == set(range(112, 128))
    # 75 deg off the boresight, in front of the radar but beyond the 60 deg half field of view.
    azimuth = math.radians(75.0)
    aside = _boxes(15 * math.cos(azimuth), 15 * math.sin(azimuth), 1.0, 1.0, azimuth, 0.0, 0.0)
    footprints = box_footprints(aside, calibration, poses, CUBE_NS, 128, 32)
    assert not footprints.in_fov.any() and footprints.outside_fov.any()
    cube = simulate_cube(PARAMS, np.array([[15 * math.cos(azimuth), 15 * math.sin(azimuth), 0.0]]), np.zeros((1, 3)),
                         [1.0], noise=0.1)
    mask = box_label_mask(cube, CUBE_NS, calibration, poses, aside)
    assert MOVING not in mask and UNCERTAIN in mask


def test_the_exact_beat_signal_of_a_car_lands_on_its_footprint():
    # A 4.5 m x 1.8 m car 14 m ahead and 2 m to the left, heading 30 deg, at 6 m/s; the ego drives
    # at 8 m/s. Scatterers on its near faces, simulated from the FMCW signal model, not the projection.
    poses = driving_poses(8.0, 0.0)
    calibration = radar_calibration(PARAMS, 0.0, (0.0, 0.0, 0.0))
    heading = math.radians(30.0)
    car_velocity = 6.0 * np.array([math.cos(heading), math.sin(heading)])
    boxes = _boxes(14.0, 2.0, 4.5, 1.8, heading, *car_velocity)
    body = np.array([(-2.25, -0.9), (-2.25, 0.0), (-2.25, 0.9), (-1.0, -0.9), (0.5, -0.9), (2.25, -0.9)])
    c, s = math.cos(heading), math.sin(heading)
    points = np.array([[14.0 + c * a - s * b, 2.0 + s * a + c * b, 0.0] for a, b in body])
    relative = np.array([*(car_velocity - [8.0, 0.0]), 0.0])
    cube = simulate_cube(PARAMS, points, np.tile(relative, (len(points), 1)), np.ones(len(points)), noise=0.05, seed=1)
    params = MaskParams()
    mask = box_label_mask(cube, CUBE_NS, calibration, poses, boxes, params)
    footprint = box_footprints(boxes, calibration, poses, CUBE_NS, *cube.shape[:2]).in_fov[0]
    # Each scatterer's own cell (range, and the Doppler of its range rate) is MOVING.
    for point in points:
        range_m = np.linalg.norm(point[:2])
        rate = point[:2] @ relative[:2] / range_m
        cell = (int(round(range_m / RANGE_BIN_M)), 16 + int(round(rate / DOPPLER_BIN_MPS)))
        assert mask[cell] == MOVING, cell
    # MOVING only within the main lobe (a bin) of the footprint, UNCERTAIN within a bin more, every
    # footprint cell classed.
    assert _cells(mask == MOVING) <= _within(footprint, 1)
    assert _cells(mask == UNCERTAIN) <= _within(footprint, 2)
    assert not (footprint & (mask == BACKGROUND)).any()
    # The CFAR-gated target covers less of the car: only the peaks' segments.
    old = cfar_peak_label_mask(cube, CUBE_NS, calibration, poses, boxes, params)
    assert (old == MOVING).sum() >= 1
    assert (mask == MOVING).sum() > (old == MOVING).sum()
    # Another box over the same cells, with nothing above the floor of its own, cannot undo a MOVING cell.
    ghost = _boxes([14.0, 14.0], [2.0, 2.0], [4.5, 6.0], [1.8, 2.5], [heading, heading], *np.tile(car_velocity[:, None], 2))
    assert _cells(mask == MOVING) <= _cells(box_label_mask(cube, CUBE_NS, calibration, poses, ghost, params) == MOVING)
    # Without boxes nothing is a car, and label_mask follows manual_targets.
    assert not box_label_mask(cube, CUBE_NS, calibration, poses, _boxes(*[[]] * 7)).any()
    assert np.array_equal(label_mask(cube, CUBE_NS, calibration, poses, boxes, params), mask)
    cfar_params = MaskParams(manual_targets="cfar-peaks")
    assert np.array_equal(label_mask(cube, CUBE_NS, calibration, poses, boxes, cfar_params), old)


def test_noise_alone_rises_above_the_floor_as_the_gamma_tail_of_four_antennas_says():
    # The power of a noise cell summed over 4 antennas is Gamma(4) distributed around its mean.
    rng = np.random.default_rng(0)
    raw = (rng.standard_normal((8, 64, 256, 4)) + 1j * rng.standard_normal((8, 64, 256, 4))) / np.sqrt(2)
    above = [
        np.mean(power_db > floor_db + DEFAULT_FLOOR_MARGIN_DB)
        for power_db, floor_db in (_power_db_and_floor(range_doppler(frame.astype(np.complex64)), MaskParams())[1:] for frame in raw)
    ]
    expected = gamma.sf(4 * 10 ** (DEFAULT_FLOOR_MARGIN_DB / 10), 4)  # 0.14 %
    assert 0.7 * expected < np.mean(above) < 1.4 * expected


def test_mask_params_check_the_target_kind_and_record_it():
    with pytest.raises(ZendarError, match="manual_targets"):
        MaskParams(manual_targets="lidar")
    with pytest.raises(ZendarError, match="floor_margin_db"):
        MaskParams(floor_margin_db=-1.0)
    # The stores record the parameters: another kind of target is another store.
    assert mask_parameters()["manual_targets"] == "boxes"
    assert mask_parameters(MaskParams(manual_targets="cfar-peaks")) != mask_parameters()
