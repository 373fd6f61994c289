"""CNN inputs: log-power maps, time stacking, the MaskFrames dataset."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from torch.utils.data import ConcatDataset

from zendar_dataset.errors import ZendarError
from zendar_dataset.format.reader import open_dataset
from zendar_dataset.sim.generate import synthesize_dataset

from zendar_baselines.cnn.maps import DB_SCALE, log_power_maps, stack_window
from zendar_baselines.cnn.mask_frames import MaskFrames


def test_stack_window_by_hand():
    maps = np.array([1.0, 2.0, 3.0, 4.0], dtype=np.float32).reshape(4, 1, 1, 1)
    stacked = stack_window(maps, 2)
    assert stacked.shape == (4, 2, 1, 1)  # one window per map: the first one padded with the first map
    assert stacked[:, :, 0, 0].tolist() == [[1, 1], [1, 2], [2, 3], [3, 4]]  # newest last


def test_stack_window_pads_a_scene_shorter_than_the_window():
    maps = np.array([5.0, 7.0], dtype=np.float32).reshape(2, 1, 1, 1)
    assert stack_window(maps, 3)[:, :, 0, 0].tolist() == [[5, 5, 5], [5, 5, 7]]


def test_stack_window_channel_is_time_major_antenna_minor():
    n_maps, n_antennas, k = 5, 3, 3
    maps = np.zeros((n_maps, n_antennas, 2, 4), dtype=np.float32)
    for frame in range(n_maps):
        for antenna in range(n_antennas):
            maps[frame, antenna] = 10 * frame + antenna
    stacked = stack_window(maps, k)
    assert stacked.shape == (n_maps, k * n_antennas, 2, 4)
    assert stacked.dtype == np.float32
    for row in range(n_maps):
        for t in range(k):
            for antenna in range(n_antennas):
                assert np.all(stacked[row, t * n_antennas + antenna] == 10 * max(row - k + 1 + t, 0) + antenna)


@pytest.mark.parametrize("k", [0, -1, 1.5])
def test_stack_window_refuses_bad_window(k):
    with pytest.raises(ZendarError, match="window k"):
        stack_window(np.zeros((5, 1, 2, 2), dtype=np.float32), k)


def test_log_power_maps_by_hand():
    # Antenna a has amplitude 10**a (a gain the median removes); one cell is 40 dB above its map.
    n_frames, n_range, n_doppler, n_antennas = 2, 5, 3, 2
    cubes = np.ones((n_frames, n_range, n_doppler, n_antennas), dtype=np.complex64)
    cubes *= (10.0 ** np.arange(n_antennas)).astype(np.complex64)
    cubes[1, 2, 1, 1] *= 100.0 * np.exp(1j * 0.7)
    maps = log_power_maps(cubes)
    assert maps.shape == (n_frames, n_antennas, n_range, n_doppler)
    assert maps.dtype == np.float32
    expected = np.zeros_like(maps)
    expected[1, 1, 2, 1] = 40.0 / DB_SCALE
    np.testing.assert_allclose(maps, expected, atol=1e-5)


def test_log_power_maps_of_complex_gaussian_noise_match_theory():
    # |x|² of circular complex Gaussian noise is exponential: 10 log10 of it has a standard
    # deviation of (10 / ln 10) * π / √6 = 5.57 dB whatever the noise power.
    rng = np.random.default_rng(0)
    shape = (3, 128, 64, 2)
    power_w = 1e-11
    cubes = (rng.normal(size=shape) + 1j * rng.normal(size=shape)) * math.sqrt(power_w / 2)
    maps = log_power_maps(cubes.astype(np.complex64))
    np.testing.assert_allclose(np.median(maps, axis=(2, 3)), 0.0, atol=1e-6)
    expected_std = 10 / math.log(10) * math.pi / math.sqrt(6) / DB_SCALE
    np.testing.assert_allclose(maps.std(axis=(2, 3)), expected_std, rtol=0.03)


def test_log_power_maps_reads_in_chunks_into_out(tmp_path):
    rng = np.random.default_rng(1)
    cubes = (rng.normal(size=(70, 4, 3, 2)) + 1j * rng.normal(size=(70, 4, 3, 2))).astype(np.complex64)
    out = np.lib.format.open_memmap(tmp_path / "maps.npy", mode="w+", dtype=np.float32, shape=(70, 2, 4, 3))
    log_power_maps(cubes, out=out)
    for frame in (0, 33, 69):  # one frame of each chunk, by hand
        power_db = 10 * np.log10(np.abs(cubes[frame].astype(np.complex128)) ** 2)
        for antenna in range(2):
            db = power_db[:, :, antenna]
            np.testing.assert_allclose(out[frame, antenna], (db - np.median(db)) / DB_SCALE, atol=1e-5)


def test_log_power_maps_refuses_real_or_misshapen_input():
    with pytest.raises(ZendarError, match="complex"):
        log_power_maps(np.zeros((2, 3, 4, 1), dtype=np.float32))
    with pytest.raises(ZendarError, match=r"\[N, R, D, A\]"):
        log_power_maps(np.zeros((3, 4, 1), dtype=np.complex64))


def test_log_power_maps_of_a_simulated_scene(tmp_path):
    root = synthesize_dataset(tmp_path / "ds", "tiny", 1, progress=False)
    index = open_dataset(root)
    scene = index.open_scene(index.scene_ids()[0])
    lazy = scene.array("radar/front_left/cube")
    maps = log_power_maps(lazy)
    n_frames, n_range, n_doppler, n_antennas = lazy.shape
    assert maps.shape == (n_frames, n_antennas, n_range, n_doppler)
    np.testing.assert_array_equal(maps, log_power_maps(np.asarray(lazy[:])))
    np.testing.assert_allclose(np.median(maps, axis=(2, 3)), 0.0, atol=1e-6)
    assert maps.max() > 2.0  # simulated targets stand more than 20 dB above the noise floor


def _maps_and_masks(n_maps=6, n_antennas=2, n_range=4, n_doppler=3):
    maps = np.arange(n_maps * n_antennas * n_range * n_doppler, dtype=np.float32).reshape(n_maps, n_antennas, n_range, n_doppler)
    masks = np.zeros((n_maps, n_range, n_doppler), dtype=np.uint8)
    for frame in range(n_maps):
        masks[frame, frame % n_range, 0] = 1
        masks[frame, (frame + 1) % n_range, 1] = 2
    return maps, masks


def test_mask_frames_pairs_each_window_with_its_newest_mask():
    maps, masks = _maps_and_masks()
    data = MaskFrames(maps, masks, window=3)
    assert len(data) == 6  # every frame, the first two with the padded windows scoring sees
    assert data.in_channels == 6
    stacked = stack_window(maps, 3)
    for index in range(len(data)):
        inputs, target = data[index]
        assert inputs.dtype == torch.float32 and target.dtype == torch.uint8
        np.testing.assert_array_equal(inputs.numpy(), stacked[index])
        np.testing.assert_array_equal(target.numpy(), masks[index])
    np.testing.assert_array_equal(data[0][0].numpy(), np.concatenate([maps[0]] * 3))
    with pytest.raises(IndexError):
        data[6]


def test_mask_frames_reads_npy_files_memory_mapped(tmp_path):
    maps, masks = _maps_and_masks()
    np.save(tmp_path / "maps.npy", maps)
    np.save(tmp_path / "masks.npy", masks)
    from_files = MaskFrames(tmp_path / "maps.npy", tmp_path / "masks.npy", window=2)
    assert isinstance(from_files.inputs, np.memmap)
    in_memory = MaskFrames(maps, masks, window=2)
    for index in range(len(in_memory)):
        for a, b in zip(from_files[index], in_memory[index]):
            assert torch.equal(a, b)
    joined = ConcatDataset([from_files, in_memory])
    assert len(joined) == 12
    assert torch.equal(joined[6][0], in_memory[0][0])


def test_mask_frames_class_counts_by_hand():
    maps, masks = _maps_and_masks()
    # Windows of 2 see the masks of frames 0..5: 12 cells each, one moving and one uncertain.
    assert MaskFrames(maps, masks, window=2).class_counts() == (6 * 10, 6)


def test_mask_frames_refuses_bad_arrays(tmp_path):
    maps, masks = _maps_and_masks()
    with pytest.raises(ZendarError, match="do not align"):
        MaskFrames(maps, masks[:, :3])
    with pytest.raises(ZendarError, match="uint8"):
        MaskFrames(maps, masks.astype(np.int64))
    with pytest.raises(ZendarError, match="window k"):
        MaskFrames(maps, masks, window=0)
    with pytest.raises(ZendarError, match="cannot read"):
        MaskFrames(tmp_path / "absent.npy", masks)
    bad = masks.copy()
    bad[4, 0, 0] = 3
    data = MaskFrames(maps, bad, window=2)
    with pytest.raises(ZendarError, match="frame 4 holds 3"):
        data[4]
