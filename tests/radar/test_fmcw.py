import numpy as np
import pytest

from zendar_dataset.errors import ZendarFormatError
from zendar_dataset.radar.fmcw import SPEED_OF_LIGHT_MPS, FmcwParams, beat_signal_exact

C = SPEED_OF_LIGHT_MPS


def test_derived_quantities(params):
    assert params.slope_hz_per_s == pytest.approx(800e6 / (64 / 10e6))
    assert params.range_bin_m == pytest.approx(C / (2 * 800e6))
    assert params.max_range_m == pytest.approx(64 * C / (2 * 800e6))
    assert params.wavelength_m == pytest.approx(C / 77e9)
    assert params.doppler_bin_mps == pytest.approx(params.wavelength_m / (2 * 32 * params.chirp_interval_s))
    assert params.max_velocity_mps == pytest.approx(16 * params.doppler_bin_mps)
    assert params.frame_duration_s == pytest.approx(32 * params.chirp_interval_s)
    assert params.n_antennas == 4


def test_single_sample_matches_the_convention(params):
    # Hand evaluation of the architecture's formula for one sample of a moving scatterer.
    x0, v = np.array([12.0, -3.0, 0.5]), np.array([4.0, 1.0, 0.0])
    m, k, a = 7, 33, 2
    t = m * params.chirp_interval_s + k / params.sample_rate_hz + 1e-3
    x = x0 + v * t
    tau = (np.linalg.norm(x) + np.linalg.norm(x - params.rx_positions_m[a])) / C
    tk = k / params.sample_rate_hz
    s = params.slope_hz_per_s
    expected = 0.5 * np.exp(2j * np.pi * (77e9 * tau + s * tau * tk - s * tau**2 / 2))
    signal = beat_signal_exact(params, x0, v, [0.5], t0_s=1e-3)
    assert signal.shape == (32, 64, 4)
    assert signal[m, k, a] == pytest.approx(expected, abs=1e-6)


def test_superposition_and_dtype(params):
    p = np.array([[10.0, 1.0, 0.0], [20.0, -2.0, 0.0]])
    v = np.zeros((2, 3))
    both = beat_signal_exact(params, p, v, [1.0, 2.0j])
    one = beat_signal_exact(params, p[:1], v[:1], [1.0]) + beat_signal_exact(params, p[1:], v[1:], [2.0j])
    np.testing.assert_allclose(both, one, atol=1e-12)
    assert beat_signal_exact(params, p, v, [1.0, 1.0], dtype=np.complex64).dtype == np.complex64


def test_antenna_phase_is_the_steering_vector(params):
    # Far-field: the phase across antennas is -2 pi u.p / lambda. At 30 m the
    # near-field and residual-video-phase terms stay below 1e-3 cycles.
    theta = np.deg2rad(25.0)
    u = np.array([np.cos(theta), np.sin(theta), 0.0])
    signal = beat_signal_exact(params, 30.0 * u, np.zeros(3), [1.0])
    measured = signal[0, 0] / signal[0, 0, 0]
    expected = np.exp(-2j * np.pi * (params.rx_positions_m @ u) / params.wavelength_m)
    np.testing.assert_allclose(measured, expected, atol=1e-2)


def test_invalid_parameters_list_every_problem():
    with pytest.raises(ZendarFormatError) as err:
        FmcwParams(-1.0, 0.0, 1e6, 0, 16, 1e-3, np.zeros((4, 2)))
    assert len(err.value.problems) == 4


def test_chirp_interval_shorter_than_sweep_is_rejected():
    with pytest.raises(ZendarFormatError, match="shorter than the sweep"):
        FmcwParams(77e9, 1e9, 1e6, 64, 16, 1e-5, np.zeros((1, 3)))


def test_calibration_round_trip(params):
    cal = params.to_calibration()
    assert set(cal) == {"center_frequency_hz", "bandwidth_hz", "range_bin_m", "doppler_bin_mps", "rx_positions_m"}
    back = FmcwParams.from_calibration(cal, n_samples=64, n_chirps=32, sample_rate_hz=params.sample_rate_hz)
    assert back.chirp_interval_s == pytest.approx(params.chirp_interval_s, rel=1e-12)
    assert back.range_bin_m == pytest.approx(params.range_bin_m)
    np.testing.assert_array_equal(back.rx_positions_m, params.rx_positions_m)
    default_rate = FmcwParams.from_calibration(cal, n_samples=64, n_chirps=32)
    assert default_rate.sample_rate_hz == pytest.approx(64 / params.chirp_interval_s)


def test_calibration_errors_are_collected(params):
    cal = params.to_calibration()
    del cal["rx_positions_m"]
    cal["bandwidth_hz"] = -5
    with pytest.raises(ZendarFormatError) as err:
        FmcwParams.from_calibration(cal, n_samples=64, n_chirps=32, where="sensors.left")
    assert any("rx_positions_m" in p for p in err.value.problems)
    assert any("sensors.left.bandwidth_hz" in p for p in err.value.problems)
    cal = params.to_calibration()
    cal["range_bin_m"] = 0.5
    with pytest.raises(ZendarFormatError, match="disagrees"):
        FmcwParams.from_calibration(cal, n_samples=64, n_chirps=32)
