"""Every chirp and every receiver in the simulated SAR: presummed pulses from the array's centre give the
image SNR of backprojecting each chirp of each receiver; the presum filter keeps every static return."""

from __future__ import annotations

import numpy as np
import pytest

from zendar_dataset.radar.range_doppler import range_profiles
from zendar_dataset.sar.grid import ImageGrid
from zendar_dataset.sim.ego import radar_params
from zendar_dataset.sim.profiles import get_profile
from zendar_dataset.sim.radar_model import synthesize_range_profiles, thermal_noise
from zendar_dataset.sim.sar_formation import (
    aperture_times,
    chirps_per_pulse,
    form_image,
    presum_factors,
    pulse_spacing_m,
    sar_waveform,
)

PARAMS = sar_waveform(radar_params(get_profile("demo")), get_profile("demo").sar_bandwidth_hz, 20.0)
SPEED_MPS = 6.0
APERTURE_M = 0.1
BORESIGHT = np.radians(45.0)
WORLD_R_SENSOR = np.array([[np.cos(BORESIGHT), -np.sin(BORESIGHT), 0.0], [np.sin(BORESIGHT), np.cos(BORESIGHT), 0.0],
                           [0.0, 0.0, 1.0]])
TARGET = 9.0 * WORLD_R_SENSOR[:, 0]


def _pulses(times_s: np.ndarray, receiver_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Noise-free profiles ``[P, N]`` of the point at ``TARGET`` for one receiver, and their phase centres."""
    radar = np.stack([SPEED_MPS * times_s, np.zeros_like(times_s), np.zeros_like(times_s)], axis=1)
    local = ((TARGET - radar) @ WORLD_R_SENSOR)[:, None, :]
    velocity = np.broadcast_to(np.array([-SPEED_MPS, 0.0, 0.0]) @ WORLD_R_SENSOR, local.shape)
    profiles = synthesize_range_profiles(PARAMS, local, velocity, np.ones((times_s.size, 1)), receiver_m)
    return profiles, radar + WORLD_R_SENSOR @ (receiver_m / 2.0)


def _snr_db(profiles: np.ndarray, noise_power: np.ndarray, centers: np.ndarray, rng: np.random.Generator) -> float:
    """Image SNR: the point's peak power over the mean power of the same pulses' noise, per pixel."""
    peak = np.abs(form_image(PARAMS, profiles, centers, ImageGrid.axis_aligned(TARGET, [1.0, 0, 0], [0, 1.0, 0], 0.1, (1, 1))))
    noise = thermal_noise(rng, (profiles.shape[0], PARAMS.n_samples, 1), 1.0)
    noise *= np.sqrt(noise_power).astype(np.float32)[:, None, None]
    grid = ImageGrid.axis_aligned(TARGET, [1.0, 0, 0], [0, 1.0, 0], 0.1, (60, 60))
    noise_image = form_image(PARAMS, range_profiles(noise, workers=1)[..., 0], centers, grid)
    return float(10.0 * np.log10(peak[0, 0] ** 2 / np.mean(np.abs(noise_image) ** 2)))


def test_presummed_pulses_from_the_array_centre_have_the_snr_of_every_chirp_of_every_receiver():
    rng = np.random.default_rng(0)
    chirp_times = np.arange(-APERTURE_M / 2, APERTURE_M / 2, SPEED_MPS * PARAMS.chirp_interval_s) / SPEED_MPS
    every = [_pulses(chirp_times, receiver) for receiver in PARAMS.rx_positions_m]
    profiles = np.concatenate([p for p, _ in every])
    centers = np.concatenate([c for _, c in every])
    reference_db = _snr_db(profiles, np.ones(profiles.shape[0]), centers, rng)

    time_s = np.arange(-1.0, 1.0, 1e-3)
    distance = SPEED_MPS * (time_s + 1.0)
    spacing = pulse_spacing_m(PARAMS)
    times = aperture_times(time_s, distance, 0.0, APERTURE_M, spacing, PARAMS.chirp_interval_s)
    chirps = chirps_per_pulse(time_s, distance, times, spacing, PARAMS.chirp_interval_s)
    assert chirps == pytest.approx(spacing / (SPEED_MPS * PARAMS.chirp_interval_s), rel=1e-6)
    presummed, centers = _pulses(times, PARAMS.rx_positions_m.mean(axis=0))
    n_rx = PARAMS.rx_positions_m.shape[0]
    assert _snr_db(presummed, 1.0 / (chirps * n_rx), centers, rng) == pytest.approx(reference_db, abs=0.5)
    # One chirp of one receiver per pulse, as the images were formed before: 10 log10(chirps * 4) dB less.
    single_db = _snr_db(*_pulses(times, PARAMS.rx_positions_m[0])[:1], np.ones(times.size), centers, rng)
    assert reference_db - single_db == pytest.approx(10 * np.log10(chirps[0] * n_rx), abs=0.5)


def test_a_stop_puts_all_its_chirps_into_one_pulse():
    time_s = np.arange(0.0, 3.0, 1e-3)
    speed = np.where(np.abs(time_s - 1.5) < 0.5, 0.0, SPEED_MPS)
    distance = np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * 1e-3)])
    spacing = pulse_spacing_m(PARAMS)
    times = aperture_times(time_s, distance, 1.5, APERTURE_M, spacing, PARAMS.chirp_interval_s)
    chirps = chirps_per_pulse(time_s, distance, times, spacing, PARAMS.chirp_interval_s)
    assert chirps.sum() * PARAMS.chirp_interval_s == pytest.approx(1.0 + (times[-1] - times[0] - 1.0) + spacing / SPEED_MPS, rel=0.01)
    assert chirps.max() * PARAMS.chirp_interval_s > 0.99


@pytest.mark.parametrize("speed_mps", [1.0, 6.5, 14.0])
def test_the_presum_filter_keeps_every_static_return_and_folds_fast_movers(speed_mps):
    spacing = pulse_spacing_m(PARAMS)
    times = np.linspace(10.0, 10.05, 7)
    # Static returns from every direction, at the top of the sweep (the shortest wavelength).
    cosines = np.linspace(-1.0, 1.0, 201)
    top = 299_792_458.0 / (PARAMS.center_frequency_hz + PARAMS.bandwidth_hz)
    static = np.repeat((2.0 * speed_mps * cosines / top)[:, None], times.size, axis=1)
    factors = presum_factors(static, times, np.full(times.size, speed_mps), spacing, PARAMS.chirp_interval_s)
    np.testing.assert_allclose(factors, 1.0)
    # A car closing at 30 m/s folds once at the chirp rate; if its folded Doppler is in the band, it
    # keeps the phase of the folded tone at each pulse.
    doppler = np.full((1, times.size), 2.0 * 30.0 / PARAMS.wavelength_m)
    folded = doppler - 1.0 / PARAMS.chirp_interval_s
    factors = presum_factors(doppler, times, np.full(times.size, speed_mps), spacing, PARAMS.chirp_interval_s)
    if abs(folded[0, 0]) <= speed_mps / (2 * spacing):
        np.testing.assert_allclose(np.exp(2j * np.pi * doppler * times) * factors,
                                   np.exp(2j * np.pi * folded * times), atol=1e-6)
    else:
        assert np.all(factors == 0.0)
