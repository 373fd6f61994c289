"""Pulse sampling of the simulated SAR: uniform along the track, no grating lobe in any direction.

A point target seen by a corner radar (boresight 45° left of the track) from a straight
track at 6.5 m/s, the demo profile's waveform; the image is read along the target's own
range circle, where every azimuth sidelobe, grating lobe and ring of the aperture lands.
"""

from __future__ import annotations

import numpy as np
import pytest

from zendar_dataset.radar.fmcw import SPEED_OF_LIGHT_MPS
from zendar_dataset.sar.grid import ImageGrid
from zendar_dataset.sim.ego import radar_params
from zendar_dataset.sim.profiles import get_profile
from zendar_dataset.sim.radar_model import synthesize_range_profiles
from zendar_dataset.sim.sar_formation import aperture_times, form_image, pulse_spacing_m, sar_waveform
from zendar_dataset.sim.trajectory import speed_profile

PROFILE = get_profile("demo")
PARAMS = sar_waveform(radar_params(PROFILE), PROFILE.sar_bandwidth_hz, 20.0)
SPEED_MPS = 6.5
RANGE_M = 10.0
TARGET_DEG = 30.0  # from the track, on the radar's side
BORESIGHT_DEG = 45.0
PIXEL_M = 0.04
WORLD_R_SENSOR = np.array([
    [np.cos(np.radians(BORESIGHT_DEG)), -np.sin(np.radians(BORESIGHT_DEG)), 0.0],
    [np.sin(np.radians(BORESIGHT_DEG)), np.cos(np.radians(BORESIGHT_DEG)), 0.0],
    [0.0, 0.0, 1.0],
])


def _target() -> np.ndarray:
    angle = np.radians(TARGET_DEG)
    return RANGE_M * np.array([np.cos(angle), np.sin(angle), 0.0])


def _ring(along_track_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Image magnitude (dB under the target's peak) on the target's range circle, and each pixel's
    angle from the track (degrees), for pulses at ``along_track_m`` (radar at the image plane's height)."""
    radar = np.stack([along_track_m, np.zeros_like(along_track_m), np.zeros_like(along_track_m)], axis=1)
    local = ((_target() - radar) @ WORLD_R_SENSOR)[:, None, :]
    velocity = np.broadcast_to(np.array([-SPEED_MPS, 0.0, 0.0]) @ WORLD_R_SENSOR, local.shape)
    profiles = synthesize_range_profiles(PARAMS, local, velocity, np.ones((radar.shape[0], 1)), np.zeros(3))
    n = int(2 * (RANGE_M + 1.0) / PIXEL_M)
    grid = ImageGrid.axis_aligned([0.0, 0.0, 0.0], [1.0, 0, 0], [0, 1.0, 0], PIXEL_M, (n, n))
    image = np.abs(form_image(PARAMS, profiles, radar, grid))
    peak = np.abs(form_image(PARAMS, profiles, radar, ImageGrid.axis_aligned(_target(), [1.0, 0, 0], [0, 1.0, 0], PIXEL_M, (1, 1))))
    centers = grid.pixel_centers()
    on_circle = np.abs(np.hypot(centers[..., 0], centers[..., 1]) - RANGE_M) < PIXEL_M
    angle_deg = np.degrees(np.arctan2(centers[..., 1], centers[..., 0]))[on_circle]
    return 20.0 * np.log10(image[on_circle] / peak[0, 0]), angle_deg


def test_pulses_are_uniform_along_the_track_and_sample_every_direction():
    # Braking to a stop and pulling away inside the aperture's time span.
    time_s, speed = speed_profile(4.0, 6.5, [(2.0, 0.5)])
    distance = np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(time_s))])
    spacing = pulse_spacing_m(PARAMS)
    for t_center in (1.0, 2.0, 2.25, 2.6):
        times = aperture_times(time_s, distance, t_center, PROFILE.sar_aperture_m, spacing, PARAMS.chirp_interval_s)
        along = np.interp(times, time_s, distance)
        steps = np.diff(along)
        assert np.all(np.abs(steps - spacing) < 1e-6 * spacing), t_center
        assert along[-1] - along[0] == pytest.approx(PROFILE.sar_aperture_m, abs=spacing)
    # Static returns span spatial frequencies 2u / lambda with |u| <= 1: lambda / 4 at the sweep's top.
    top_wavelength = SPEED_OF_LIGHT_MPS / (PARAMS.center_frequency_hz + PARAMS.bandwidth_hz)
    assert spacing <= top_wavelength / 4


def test_no_grating_lobe_anywhere_on_the_range_circle_behind_the_radar():
    spacing = pulse_spacing_m(PARAMS)
    n = int(PROFILE.sar_aperture_m / spacing) + 1
    level_db, angle_deg = _ring((np.arange(n) - (n - 1) / 2) * spacing)
    # More than 120 deg from the track, behind the antenna's half-plane where no return exists: where
    # the grating lobes of a spacing that samples only that half-plane land (u <= 1 - 1.71, below).
    behind = np.abs(angle_deg) > 120.0
    assert behind.sum() > 100
    assert level_db[behind].max() <= -50.0
    # The spacing that samples only the radar's forward half-plane, lambda / (2 (1 + cos 45 deg)), puts
    # the target's grating lobe at u = cos 30 deg - (1 + cos 45 deg), about 153 deg from the track: seen.
    half_plane = PARAMS.wavelength_m / (2.0 * (1.0 + np.cos(np.radians(45.0))))
    m = int(PROFILE.sar_aperture_m / half_plane) + 1
    level_db, angle_deg = _ring((np.arange(m) - (m - 1) / 2) * half_plane)
    lobe_deg = np.degrees(np.arccos(np.cos(np.radians(TARGET_DEG)) - PARAMS.wavelength_m / (2.0 * half_plane)))
    near_lobe = np.abs(np.abs(angle_deg) - lobe_deg) < 2.0
    assert level_db[near_lobe].max() > -10.0


def test_a_point_leaves_no_ring_on_its_range_circle():
    # The simulated image (uniform pulses, Hann taper along the aperture): away from the target and its
    # left-right mirror across the track (same range and angle to the track, the ambiguity of a
    # straight aperture), the range circle stays 50 dB under the peak.
    spacing = pulse_spacing_m(PARAMS)
    n = int(PROFILE.sar_aperture_m / spacing) + 1
    level_db, angle_deg = _ring((np.arange(n) - (n - 1) / 2) * spacing)
    away = (np.abs(angle_deg - TARGET_DEG) > 10.0) & (np.abs(angle_deg + TARGET_DEG) > 10.0)
    assert away.sum() > 1000
    assert level_db[away].max() <= -50.0
