import numpy as np
import pytest
import torch
from tests.radar.radar_helpers import ula_params

from zendar_dataset.radar.cfar import METHODS, cfar_2d, detect
from zendar_dataset.radar.doa import estimate_azimuth
from zendar_dataset.radar.fmcw import beat_signal_exact
from zendar_dataset.radar.batched_chain import RadarChain, cfar_torch
from zendar_dataset.radar.range_doppler import range_doppler

CFAR = dict(guard=(2, 2), train=(6, 4), pfa=1e-5)


def _frames(params, n_frames=3, seed=0):
    rng = np.random.default_rng(seed)
    rb, db = params.range_bin_m, params.doppler_bin_mps
    positions = [[40 * rb * np.cos(0.3), 40 * rb * np.sin(0.3), 0.0], [70 * rb * np.cos(-0.2), 70 * rb * np.sin(-0.2), 0.0]]
    velocities = [[5 * db, 0, 0], [0, 0, 0]]
    out = []
    for _ in range(n_frames):
        s = beat_signal_exact(params, positions, velocities, [0.2, 0.2])
        out.append(s + (rng.standard_normal(s.shape) + 1j * rng.standard_normal(s.shape)) / np.sqrt(2))
    return np.array(out).astype(np.complex64)


@pytest.mark.parametrize("method", METHODS)
def test_torch_cfar_matches_numpy(method):
    rng = np.random.default_rng(1)
    power = rng.exponential(size=(2, 64, 32)).astype(np.float32)
    mask, threshold, noise = cfar_torch(torch.from_numpy(power), method=method, **CFAR)
    expected = cfar_2d(power.astype(np.float64), method=method, **CFAR)
    np.testing.assert_allclose(threshold.numpy(), expected.threshold, rtol=1e-5)
    np.testing.assert_allclose(noise.numpy(), expected.noise_power, rtol=1e-5)
    near_threshold = np.abs(power / expected.threshold - 1) < 1e-5
    np.testing.assert_array_equal(mask.numpy()[~near_threshold], expected.mask[~near_threshold])


@pytest.mark.parametrize("doa_method", ["bartlett", "capon", "music"])
def test_chain_matches_the_numpy_functions(doa_method):
    params = ula_params(n_samples=128, n_chirps=64, n_antennas=4)
    frames = _frames(params)
    dets = RadarChain(params, cfar=dict(method="ca", **CFAR), doa_method=doa_method).from_raw(frames)
    assert set(dets.frame_index.tolist()) == {0, 1, 2}
    for i in range(3):
        cube = range_doppler(frames[i])
        ref = detect(cube, params, method="ca", **CFAR)
        sel = dets.frame_index == i
        np.testing.assert_array_equal(dets.range_bin[sel].numpy(), ref.range_bin)
        np.testing.assert_array_equal(dets.doppler_bin[sel].numpy(), ref.doppler_bin)
        np.testing.assert_allclose(dets.range_m[sel].numpy(), ref.range_m, rtol=1e-6)
        np.testing.assert_allclose(dets.velocity_mps[sel].numpy(), ref.velocity_mps, rtol=1e-6)
        np.testing.assert_allclose(dets.snr_db[sel].numpy(), ref.snr_db, atol=1e-3)
        az = estimate_azimuth(cube[ref.range_bin, ref.doppler_bin], params.rx_positions_m, params.wavelength_m, method=doa_method)
        np.testing.assert_allclose(dets.azimuth_rad[sel].numpy(), az, atol=2e-3)
    # both targets found in every frame, near their true azimuths
    assert sorted(set(dets.range_bin.tolist())) == [40, 70]
    for rbin, truth in ((40, 0.3), (70, -0.2)):
        assert np.abs(dets.azimuth_rad[dets.range_bin == rbin].numpy() - truth).max() < 0.05


def test_chain_from_cubes_equals_from_raw():
    params = ula_params(n_samples=128, n_chirps=64, n_antennas=4)
    frames = _frames(params, n_frames=2, seed=4)
    chain = RadarChain(params, cfar=dict(method="os", **CFAR))
    a = chain.from_raw(frames)
    b = chain.from_cubes(range_doppler(frames))
    torch.testing.assert_close(a.range_bin, b.range_bin)
    torch.testing.assert_close(a.azimuth_rad, b.azimuth_rad, atol=1e-4, rtol=0)


def test_chain_rejects_wrong_shapes():
    params = ula_params(n_samples=128, n_chirps=64, n_antennas=4)
    chain = RadarChain(params)
    with pytest.raises(ValueError, match="frames must be"):
        chain.from_raw(np.zeros((2, 64, 100, 4), np.complex64))
    with pytest.raises(ValueError, match="cubes must be"):
        chain.from_cubes(np.zeros((2, 128, 64, 3), np.complex64))
    with pytest.raises(ValueError, match="doa_method"):
        RadarChain(params, doa_method="esprit")


@pytest.mark.gpu
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_chain_on_cuda_matches_cpu():
    params = ula_params(n_samples=128, n_chirps=64, n_antennas=4)
    frames = _frames(params)
    cpu = RadarChain(params, cfar=dict(method="go", **CFAR)).from_raw(frames)
    gpu = RadarChain(params, device="cuda", cfar=dict(method="go", **CFAR)).from_raw(frames)
    torch.testing.assert_close(gpu.range_bin.cpu(), cpu.range_bin)
    torch.testing.assert_close(gpu.doppler_bin.cpu(), cpu.doppler_bin)
    torch.testing.assert_close(gpu.azimuth_rad.cpu(), cpu.azimuth_rad, atol=1e-3, rtol=0)
    torch.testing.assert_close(gpu.snr_db.cpu(), cpu.snr_db, atol=1e-3, rtol=0)
