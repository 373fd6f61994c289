"""Fast cube and range-profile synthesis against the exact per-sample model and closed-form physics."""

import numpy as np
import pytest

from zendar_dataset.radar.fmcw import SPEED_OF_LIGHT_MPS, FmcwParams, beat_signal_exact
from zendar_dataset.radar.range_doppler import range_doppler, range_profiles
from zendar_dataset.sim.radar_model import synthesize_cube, synthesize_range_profiles

WAVELENGTH = SPEED_OF_LIGHT_MPS / 77e9


def _params(n_samples=128, n_chirps=64):
    rx = np.zeros((4, 3))
    rx[:, 1] = (np.arange(4) - 1.5) * WAVELENGTH / 2
    chirp = WAVELENGTH / (4 * 20.0)
    return FmcwParams(77e9, SPEED_OF_LIGHT_MPS / (2 * 0.18), n_samples / (0.85 * chirp), n_samples, n_chirps, chirp, rx)


def _targets(rng, n, params):
    r = rng.uniform(3.0, params.max_range_m - 3.0, n)
    az = rng.uniform(-1.0, 1.0, n)
    pos = np.stack([r * np.cos(az), r * np.sin(az), rng.uniform(-0.3, 0.3, n)], axis=1)
    vel = np.concatenate([rng.uniform(-12, 12, (n, 2)), np.zeros((n, 1))], axis=1)
    amp = rng.normal(size=n) + 1j * rng.normal(size=n)
    return pos, vel, amp


def _per_chirp(params, pos, vel):
    t = np.arange(params.n_chirps) * params.chirp_interval_s
    return pos[:, None, :] + vel[:, None, :] * t[None, :, None]


def test_fast_cube_matches_exact_model_with_20_targets():
    params = _params()
    pos, vel, amp = _targets(np.random.default_rng(1), 20, params)
    exact = range_doppler(beat_signal_exact(params, pos, vel, amp))
    fast = synthesize_cube(params, _per_chirp(params, pos, vel), amp)
    assert np.linalg.norm(fast - exact) / np.linalg.norm(exact) < 0.01


def test_fast_range_profiles_match_exact_model():
    params = _params(n_chirps=8)
    pos, vel, amp = _targets(np.random.default_rng(2), 10, params)
    exact = range_profiles(beat_signal_exact(params, pos, vel, amp))[..., 0]
    per_chirp = _per_chirp(params, pos, vel).transpose(1, 0, 2)
    fast = synthesize_range_profiles(
        params, per_chirp, np.broadcast_to(vel, per_chirp.shape), np.broadcast_to(amp, per_chirp.shape[:2]),
        params.rx_positions_m[0],
    )
    assert np.linalg.norm(fast - exact) / np.linalg.norm(exact) < 0.01


def _width_3db(values):
    """Width (in samples) of the -3 dB main lobe of a peaked 1-D power curve, linearly interpolated."""
    peak = int(np.argmax(values))
    half = values[peak] / 2
    lo = peak
    while values[lo - 1] > half:
        lo -= 1
    hi = peak
    while values[hi + 1] > half:
        hi += 1
    left = lo - 1 + (half - values[lo - 1]) / (values[lo] - values[lo - 1])
    right = hi + (values[hi] - half) / (values[hi] - values[hi + 1])
    return right - left


def test_point_target_peak_bins_widths_and_azimuth():
    params = _params(n_samples=256, n_chirps=128)
    range_m, velocity, azimuth = 20.07, 3.3, np.radians(20.0)
    u = np.array([np.cos(azimuth), np.sin(azimuth), 0.0])
    cube = synthesize_cube(params, _per_chirp(params, (range_m * u)[None], (velocity * u)[None]), np.ones(1))
    power = np.abs(cube[..., 0]) ** 2
    r, d = np.unravel_index(np.argmax(power), power.shape)
    assert r == round(range_m / params.range_bin_m + 77e9 * 2 * velocity / SPEED_OF_LIGHT_MPS * params.sweep_duration_s)
    assert d == params.n_chirps // 2 + round(velocity / params.doppler_bin_mps)
    # The -3 dB width, measured by sweeping the target through one fixed cell in
    # small steps; a Hann window widens it to 1.44 x c/2B and 1.44 x lambda/(2 D T_c).
    steps = np.linspace(-2.0, 2.0, 161)
    static = 0.0 * u
    range_curve = np.array([
        abs(synthesize_cube(params, _per_chirp(params, ((r + s) * params.range_bin_m * u)[None], static[None]), np.ones(1))[r, params.n_chirps // 2, 0]) ** 2
        for s in steps
    ])
    doppler_curve = np.array([
        abs(synthesize_cube(params, _per_chirp(params, (10.0 * u)[None], ((5 + s) * params.doppler_bin_mps * u)[None]), np.ones(1))[:, params.n_chirps // 2 + 5, 0]).max() ** 2
        for s in steps
    ])
    range_width_m = _width_3db(range_curve) * (steps[1] - steps[0]) * params.range_bin_m
    doppler_width = _width_3db(doppler_curve) * (steps[1] - steps[0]) * params.doppler_bin_mps
    assert range_width_m == pytest.approx(1.44 * SPEED_OF_LIGHT_MPS / (2 * params.bandwidth_hz), rel=0.1)
    assert doppler_width == pytest.approx(1.44 * WAVELENGTH / (2 * params.n_chirps * params.chirp_interval_s), rel=0.1)
    # Steering a_a = exp(-j 2 pi u.p_a / lambda): the phase step between antennas gives the azimuth.
    step = np.angle(np.sum(cube[r, d, 1:] * np.conj(cube[r, d, :-1])))
    estimated = np.arcsin(-step * WAVELENGTH / (2 * np.pi * WAVELENGTH / 2))
    assert np.degrees(abs(estimated - azimuth)) < 0.5
