"""Optional CNN input channels, against physics: point targets simulated sample by sample
(``beat_signal_exact``) seen by a radar on a car that drives and turns.

- The phase between neighbouring antennas of a target's cell is the plane wave's
  ``-2π Δy sin θ / λ`` at its azimuth.
- The static Doppler channel of a static target's cell is ~0 while the ego drives at 10 m/s (its raw
  Doppler is several metres per second), and a mover's is its own radial speed over ground.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.detection.chain_helpers import T0_NS, driving_poses, radar_calibration, radar_params, simulate_cube
from zendar_baselines.bench.steps import scene_maps
from zendar_baselines.cnn.input_channels import (
    InputChannels, input_maps, phase_difference_maps, scene_input_maps, static_doppler_maps,
)
from zendar_baselines.cnn.maps import log_power_maps
from zendar_dataset.errors import ZendarError
from zendar_dataset.format.reader import open_dataset
from zendar_dataset.sim.generate import synthesize_dataset

MOUNT_YAW_RAD = math.radians(30.0)
MOUNT_M = (1.0, 0.5, 0.6)
SPEED_MPS, YAW_RATE_RAD_S = 10.0, 0.2


def _peak(cube: np.ndarray) -> tuple[int, int]:
    power = (np.abs(cube) ** 2).sum(axis=-1)
    return np.unravel_index(int(np.argmax(power)), power.shape)


@pytest.mark.parametrize("azimuth_deg", [-35.0, -8.0, 0.0, 12.0, 40.0])
def test_the_phase_between_neighbouring_antennas_is_the_plane_waves(azimuth_deg):
    params = radar_params(n_samples=128)
    azimuth_rad = math.radians(azimuth_deg)
    direction = np.array([math.cos(azimuth_rad), math.sin(azimuth_rad), 0.0])
    cube = simulate_cube(params, 15.0 * direction, np.zeros(3), [1.0], noise=1e-3)
    r, d = _peak(cube)
    maps = phase_difference_maps(cube[None])[0]
    assert maps.shape == (6, *cube.shape[:2]) and maps.dtype == np.float32
    spacing_m = np.diff(params.rx_positions_m[:, 1])
    expected = -2 * math.pi * spacing_m * math.sin(azimuth_rad) / params.wavelength_m
    np.testing.assert_allclose(maps[0::2, r, d], np.cos(expected), atol=0.02)
    np.testing.assert_allclose(maps[1::2, r, d], np.sin(expected), atol=0.02)
    np.testing.assert_allclose(maps[0::2] ** 2 + maps[1::2] ** 2, 1.0, atol=1e-5)


def _radar_velocity_radar_frame() -> np.ndarray:
    """The mount's velocity over ground at T0 in the radar's axes, by hand: v + ω × r, then the mount's yaw undone."""
    velocity_ego = np.array([SPEED_MPS - YAW_RATE_RAD_S * MOUNT_M[1], YAW_RATE_RAD_S * MOUNT_M[0], 0.0])
    cos, sin = math.cos(MOUNT_YAW_RAD), math.sin(MOUNT_YAW_RAD)
    return np.array([cos * velocity_ego[0] + sin * velocity_ego[1], -sin * velocity_ego[0] + cos * velocity_ego[1], 0.0])


@pytest.mark.parametrize("azimuth_deg", [-30.0, 5.0, 25.0])
def test_a_static_target_reads_zero_and_a_mover_its_own_radial_speed(azimuth_deg):
    params = radar_params(n_samples=128, n_chirps=128)  # 0.76 m/s Doppler bins
    calibration = radar_calibration(params, MOUNT_YAW_RAD, MOUNT_M)
    poses = driving_poses(SPEED_MPS, YAW_RATE_RAD_S)
    azimuth_rad = math.radians(azimuth_deg)
    direction = np.array([math.cos(azimuth_rad), math.sin(azimuth_rad), 0.0])
    radar_velocity = _radar_velocity_radar_frame()
    half_span_mps = params.n_chirps * params.doppler_bin_mps / 2
    for own_radial_mps in (0.0, 3.0, -4.0):
        # Relative to the radar, a point fixed to the ground moves at -v_radar.
        cube = simulate_cube(params, 15.0 * direction, -radar_velocity + own_radial_mps * direction, [1.0], noise=1e-3)
        r, d = _peak(cube)
        raw_radial_mps = (d - cube.shape[1] // 2) * params.doppler_bin_mps
        channel = static_doppler_maps(cube[None], np.array([T0_NS]), calibration, poses)
        assert channel.shape == (1, 1, *cube.shape[:2])
        assert abs(raw_radial_mps - own_radial_mps) > 3.0  # the ego's motion alone moves the target by bins
        assert channel[0, 0, r, d] * half_span_mps == pytest.approx(own_radial_mps, abs=params.doppler_bin_mps)
        assert np.all(np.abs(channel) <= 1.0)


def test_input_maps_stack_the_log_power_then_the_phases_then_the_residual():
    params = radar_params(n_samples=64, n_chirps=32)
    calibration = radar_calibration(params, MOUNT_YAW_RAD, MOUNT_M)
    poses = driving_poses(SPEED_MPS, YAW_RATE_RAD_S)
    direction = np.array([0.9, 0.3, 0.0]) / math.hypot(0.9, 0.3)
    cubes = np.stack([simulate_cube(params, 8.0 * direction, np.zeros(3), [1.0], noise=1e-2, seed=seed) for seed in range(2)])
    times = np.array([T0_NS, T0_NS + 100_000_000])
    both = InputChannels(phase_differences=True, static_doppler=True)
    maps = input_maps(cubes, both, timestamps_ns=times, calibration=calibration, poses=poses)
    assert maps.shape == (2, both.channels_per_map(4), 64, 32) == (2, 11, 64, 32)
    np.testing.assert_array_equal(maps[:, :4], log_power_maps(cubes))
    np.testing.assert_array_equal(maps[:, 4:10], phase_difference_maps(cubes))
    np.testing.assert_array_equal(maps[:, 10:], static_doppler_maps(cubes, times, calibration, poses))
    np.testing.assert_array_equal(input_maps(cubes, InputChannels()), log_power_maps(cubes))
    with pytest.raises(ZendarError, match="static Doppler channel needs"):
        input_maps(cubes, InputChannels(static_doppler=True))
    with pytest.raises(ZendarError, match="out must be float32 of shape"):
        input_maps(cubes, both, timestamps_ns=times, calibration=calibration, poses=poses, out=np.zeros((2, 4, 64, 32), np.float32))


def test_channel_sets_name_count_and_round_trip_through_a_checkpoints_record():
    assert InputChannels().is_paper_input and InputChannels().to_json() is None
    assert InputChannels.from_json(None) == InputChannels()
    for channels, name, per_map in [(InputChannels(True, False), "power+phase", 10),
                                    (InputChannels(False, True), "power+static-doppler", 5),
                                    (InputChannels(True, True), "power+phase+static-doppler", 11)]:
        assert channels.name == name and channels.channels_per_map(4) == per_map
        assert InputChannels.from_json(channels.to_json()) == channels
    for junk in ({"phase_differences": 1, "static_doppler": False}, {"phase": True}, "power"):
        with pytest.raises(ZendarError, match="input channels: expected"):
            InputChannels.from_json(junk)


def test_scene_maps_are_cached_per_channel_set_and_agree_with_the_paper_input(tmp_path):
    root = synthesize_dataset(tmp_path / "ds", "tiny", 1, progress=False)
    index = open_dataset(root)
    with index.open_scene(index.scene_ids()[0]) as reader:
        radar = reader.sensors("radar")[0]
        plain = scene_maps(reader, radar, tmp_path / "cache")
        both = InputChannels(phase_differences=True, static_doppler=True)
        extended = scene_maps(reader, radar, tmp_path / "cache", both)
        n_antennas = reader.array(f"radar/{radar}/cube").shape[3]
        assert extended.shape[1] == both.channels_per_map(n_antennas) and plain.shape[1] == n_antennas
        np.testing.assert_array_equal(extended[:, :n_antennas], plain)
        np.testing.assert_array_equal(extended, scene_input_maps(reader, radar, both))
        assert sorted(path.name for path in (tmp_path / "cache").iterdir()) == sorted(
            [f"{reader.scene_id}__{radar}.npy", f"{reader.scene_id}__{radar}__power+phase+static-doppler.npy"])
        # The static targets of the scene (most CFAR-bright cells) sit near 0 in the residual channel.
        strong = extended[:, 0] > 3.0
        assert np.median(np.abs(extended[:, -1][strong])) < 0.1

