import numpy as np
import pytest
import torch

from zendar_dataset.radar.fmcw import SPEED_OF_LIGHT_MPS, beat_signal_exact
from zendar_dataset.radar.range_doppler import (
    range_axis_m,
    range_doppler,
    range_profiles,
    velocity_axis_mps,
    window_values,
)

from tests.radar.radar_helpers import ula_params

# 3-dB main-lobe width of the Hann window, in DFT bins (Harris 1978, Table 1).
HANN_3DB_WIDTH_BINS = 1.44


def _peak(cube):
    power = np.sum(np.abs(cube) ** 2, axis=-1)
    return np.unravel_index(np.argmax(power), power.shape)


def test_point_target_lands_on_its_bins(params):
    range_m = 20 * params.range_bin_m
    velocity = 5 * params.doppler_bin_mps
    cube = range_doppler(beat_signal_exact(params, [range_m, 0, 0], [velocity, 0, 0], [1.0]))
    assert cube.shape == (64, 32, 4)
    r, d = _peak(cube)
    assert (r, d) == (20, 16 + 5)
    assert range_axis_m(64, params.range_bin_m)[r] == pytest.approx(range_m)
    assert velocity_axis_mps(32, params.doppler_bin_mps)[d] == pytest.approx(velocity)


def test_approaching_target_has_negative_velocity_bin(params):
    cube = range_doppler(beat_signal_exact(params, [10 * params.range_bin_m, 0, 0], [-3 * params.doppler_bin_mps, 0, 0], [1.0]))
    assert _peak(cube) == (10, 16 - 3)


def test_bin_centred_tone_peak_value_is_window_sum(params):
    cube = range_doppler(beat_signal_exact(params, [20 * params.range_bin_m, 0, 0], [0, 0, 0], [1.0]))
    expected = window_values("hann", 64).sum() * window_values("hann", 32).sum()
    assert np.abs(cube[20, 16, 0]) == pytest.approx(expected, rel=2e-3)


def _three_db_width(offsets, response):
    half = response.max() / 2
    above = offsets[response >= half]
    return above.max() - above.min()


def test_range_resolution_is_c_over_2b_times_hann_factor():
    params = ula_params(n_samples=64, n_chirps=4, n_antennas=1)
    offsets = np.linspace(-1.5, 1.5, 121)  # in bins
    response = []
    for off in offsets:
        cube = range_doppler(beat_signal_exact(params, [(20 + off) * params.range_bin_m, 0, 0], [0, 0, 0], [1.0]))
        response.append(np.abs(cube[20, 2, 0]) ** 2)
    width_m = _three_db_width(offsets, np.array(response)) * params.range_bin_m
    expected = HANN_3DB_WIDTH_BINS * SPEED_OF_LIGHT_MPS / (2 * params.bandwidth_hz)
    assert width_m == pytest.approx(expected, rel=0.04)


def test_doppler_resolution_is_lambda_over_2dtc_times_hann_factor():
    params = ula_params(n_samples=16, n_chirps=64, n_antennas=1)
    offsets = np.linspace(-1.5, 1.5, 121)
    response = []
    for off in offsets:
        cube = range_doppler(beat_signal_exact(params, [4 * params.range_bin_m, 0, 0], [off * params.doppler_bin_mps, 0, 0], [1.0]))
        response.append(np.abs(cube[4, 32, 0]) ** 2)
    width_mps = _three_db_width(offsets, np.array(response)) * params.doppler_bin_mps
    expected = HANN_3DB_WIDTH_BINS * params.wavelength_m / (2 * params.n_chirps * params.chirp_interval_s)
    assert width_mps == pytest.approx(expected, rel=0.04)


def test_white_noise_power_per_cell():
    rng = np.random.default_rng(3)
    raw = (rng.standard_normal((8, 64, 128, 1)) + 1j * rng.standard_normal((8, 64, 128, 1))) / np.sqrt(2)
    cube = range_doppler(raw, range_window="hamming", doppler_window="blackman")
    expected = np.sum(window_values("hamming", 128) ** 2) * np.sum(window_values("blackman", 64) ** 2)
    assert np.mean(np.abs(cube) ** 2) == pytest.approx(expected, rel=0.02)


def test_zero_padding_and_cropping(params):
    raw = beat_signal_exact(params, [20 * params.range_bin_m, 0, 0], [0, 0, 0], [1.0])
    padded = range_doppler(raw, n_range_bins=256)
    assert padded.shape == (256, 32, 4)
    assert _peak(padded) == (80, 16)
    cropped = range_doppler(raw, n_range_bins=32)
    np.testing.assert_allclose(cropped, range_doppler(raw)[:32], rtol=1e-12, atol=1e-9)


def test_odd_chirp_count_puts_zero_velocity_in_the_centre():
    params = ula_params(n_samples=32, n_chirps=31, n_antennas=1)
    cube = range_doppler(beat_signal_exact(params, [5 * params.range_bin_m, 0, 0], [2 * params.doppler_bin_mps, 0, 0], [1.0]))
    assert _peak(cube) == (5, 15 + 2)


def test_matches_a_plain_numpy_reference(params):
    rng = np.random.default_rng(0)
    raw = rng.standard_normal((2, 32, 64, 4)) + 1j * rng.standard_normal((2, 32, 64, 4))
    w_r, w_d = window_values("hann", 64), window_values("hamming", 32)
    ref = np.fft.fftshift(np.fft.fft(np.fft.fft(raw * w_r[:, None], axis=-2) * w_d[:, None, None], axis=-3), axes=-3)
    np.testing.assert_allclose(range_doppler(raw, doppler_window="hamming"), np.swapaxes(ref, -3, -2), rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(range_profiles(raw), np.fft.fft(raw * w_r[:, None], axis=-2), rtol=1e-10, atol=1e-9)


def test_explicit_and_rect_windows(params):
    rng = np.random.default_rng(1)
    raw = rng.standard_normal((32, 64, 4)) + 1j * rng.standard_normal((32, 64, 4))
    np.testing.assert_allclose(
        range_doppler(raw, range_window=np.ones(64), doppler_window=None), range_doppler(raw, range_window="rect", doppler_window="rect")
    )
    with pytest.raises(ValueError, match="shape"):
        range_doppler(raw, range_window=np.ones(3))
    with pytest.raises(ValueError, match="unknown window"):
        range_doppler(raw, range_window="no-such-window")
    with pytest.raises(ValueError, match="n_chirps, n_samples, A"):
        range_doppler(raw[0])


@pytest.mark.parametrize("n_range_bins", [None, 96])
def test_numpy_and_torch_cpu_agree(n_range_bins):
    rng = np.random.default_rng(2)
    raw = (rng.standard_normal((3, 32, 64, 4)) + 1j * rng.standard_normal((3, 32, 64, 4))).astype(np.complex64)
    expected = range_doppler(raw, n_range_bins=n_range_bins)
    got = range_doppler(torch.from_numpy(raw), n_range_bins=n_range_bins)
    assert isinstance(got, torch.Tensor) and got.dtype == torch.complex64
    scale = np.abs(expected).max()
    np.testing.assert_allclose(got.numpy(), expected, atol=1e-5 * scale)
    prof = range_profiles(torch.from_numpy(raw), n_range_bins=n_range_bins).numpy()
    np.testing.assert_allclose(prof, range_profiles(raw, n_range_bins=n_range_bins), atol=1e-5 * np.abs(prof).max())


@pytest.mark.gpu
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_numpy_and_torch_cuda_agree():
    rng = np.random.default_rng(2)
    raw = (rng.standard_normal((3, 32, 64, 4)) + 1j * rng.standard_normal((3, 32, 64, 4))).astype(np.complex64)
    expected = range_doppler(raw)
    got = range_doppler(torch.from_numpy(raw).cuda()).cpu().numpy()
    np.testing.assert_allclose(got, expected, atol=1e-5 * np.abs(expected).max())
