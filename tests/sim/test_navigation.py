"""The written tracklog's error: centimetres off, smooth over a synthetic aperture, held while the ego
stands; a static point focuses from it as from the truth; frames whose aperture spans a stop are marked."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from zendar_dataset.geometry.geodesy import LocalENU
from zendar_dataset.geometry.poses import PoseInterpolator
from zendar_dataset.sar.grid import ImageGrid
from zendar_dataset.sim import ego as ego_model
from zendar_dataset.sim.profiles import get_profile
from zendar_dataset.sim.radar_model import synthesize_range_profiles
from zendar_dataset.sim.rotate import rotate, unrotate
from zendar_dataset.sim.sar_formation import aperture_times, form_image, pulse_spacing_m, sar_waveform
from zendar_dataset.sim.scene import SceneTruth, ego_poses_from_tracklog
from zendar_dataset.sim.trajectory import Trajectory, speed_profile
from zendar_dataset.sim.world import World

ENU = LocalENU(37.77, -122.42, 10.0)
START_NS = 1_300_000_000_000_000_000
SENSOR = "front_left"


def _straight(duration_s: float, cruise_mps: float, stops=()) -> Trajectory:
    """A straight drive east, with full stops ``(time_s, wait_s)``."""
    time_s, speed = speed_profile(duration_s, cruise_mps, list(stops))
    position = np.zeros((time_s.size, 3))
    position[:, 0] = np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(time_s))])
    return Trajectory(time_s, position, np.zeros(time_s.size), speed)


def _position_error(trajectory: Trajectory, seed: int, end_s: float) -> tuple[np.ndarray, np.ndarray]:
    truth, written = ego_model.make_tracklogs(trajectory, ENU, START_NS, 0.0, end_s, np.random.default_rng(seed))
    seconds = (truth.timestamp_ns - START_NS) / 1e9
    return seconds, ENU.ecef_to_enu(written.position_ecef) - ENU.ecef_to_enu(truth.position_ecef)


def test_the_written_tracklog_is_centimetres_off_and_straight_within_a_hundredth_of_a_millimetre_over_2_m():
    seconds, error = _position_error(_straight(121.0, 10.0), 0, 120.0)
    assert 0.003 < np.sqrt(np.mean(error**2)) < 0.06
    # 2 m at 10 m/s: every 0.2 s stretch stays within 0.1 mm of a straight line (a wavelength is 3.9 mm).
    window = 21
    worst = 0.0
    for start in range(0, seconds.size - window, window):
        t = seconds[start : start + window]
        design = np.stack([np.ones(window), t - t[0]], axis=1)
        fit, *_ = np.linalg.lstsq(design, error[start : start + window], rcond=None)
        worst = max(worst, float(np.abs(error[start : start + window] - design @ fit).max()))
    assert worst < 1e-4


def test_zero_velocity_updates_hold_the_position_error_while_the_ego_stands():
    seconds, error = _position_error(_straight(10.0, 8.0, [(5.0, 1.0)]), 1, 9.0)
    standing = (seconds > 5.05) & (seconds < 5.95)
    assert standing.sum() > 80
    assert np.ptp(error[standing], axis=0).max() < 2e-5
    moving = (seconds > 1.0) & (seconds < 2.0)
    assert np.ptp(error[moving], axis=0).max() > 0.0


def _peak(params, profiles, centers, grid) -> float:
    return float(np.abs(form_image(params, profiles, centers, grid)).max())


@pytest.mark.parametrize(
    ("aperture_m", "stops", "t_image_s"),
    [(0.25, (), 4.5), (2.0, (), 4.5), (0.25, [(4.0, 1.0)], 4.5), (2.0, [(4.0, 1.0)], 4.5)],
    ids=["0.25 m", "2 m", "0.25 m, ego stopped", "2 m, ego stopped"],
)
def test_a_static_point_focuses_from_the_written_tracklog_within_1_db_of_the_truth(aperture_m, stops, t_image_s):
    """A point 8 m along the radar's boresight (paper waveform, 4 cm range resolution), imaged from the
    same simulated pulses with phase centres from the written and from the true tracklog, for several
    draws of the navigation error: the written one's peak (sought around the point, which the
    centimetres of bias displace) stays within 1 dB of the true one's."""
    profile = get_profile("paper")
    trajectory = _straight(8.0, 6.0, stops)
    params = sar_waveform(ego_model.radar_params(profile), profile.sar_bandwidth_hz, 12.0)
    distance = np.concatenate([[0.0], np.cumsum(0.5 * (trajectory.speed_mps[1:] + trajectory.speed_mps[:-1]) * 1e-3)])
    times = aperture_times(trajectory.time_s, distance, t_image_s, aperture_m, pulse_spacing_m(params),
                           params.chirp_interval_s)
    assert ego_model.stood_still(trajectory, times[0], times[-1]) == bool(stops)
    mount = ego_model.EGO_T_SENSOR[SENSOR]
    rotation, position = ego_model.sensor_poses_enu(trajectory, SENSOR, np.array(t_image_s))
    target = position + 8.0 * rotation[:, 0]
    rotations, positions = ego_model.sensor_poses_enu(trajectory, SENSOR, times)
    local = unrotate(rotations, target - positions)[:, None, :]
    rotations_later, positions_later = ego_model.sensor_poses_enu(trajectory, SENSOR, times + 1e-4)
    later = unrotate(rotations_later, target - positions_later)[:, None, :]
    profiles = synthesize_range_profiles(params, local, (later - local) / 1e-4, np.ones((times.size, 1)), np.zeros(3))
    grid = ImageGrid.axis_aligned(target, [1.0, 0, 0], [0, 1.0, 0], 0.003, (101, 101))
    losses = []
    for seed in range(4):
        truth_log, written_log = ego_model.make_tracklogs(trajectory, ENU, START_NS, 0.01, 7.99, np.random.default_rng(seed))
        peaks = []
        for log in (truth_log, written_log):
            scene = SceneTruth(World(None, None, None, [], []), trajectory, truth_log, written_log, ENU, START_NS)
            interpolator = PoseInterpolator(log.timestamp_ns, log.position_ecef, log.attitude_wxyz)
            ego_r, ego_t = ego_poses_from_tracklog(scene, interpolator, times)
            centers = ego_t + rotate(ego_r, np.asarray(mount.translation))
            peaks.append(_peak(params, profiles, centers, grid))
        losses.append(20.0 * np.log10(peaks[1] / peaks[0]))
    assert min(losses) > -1.0, losses


def test_frames_whose_aperture_spans_a_stop_are_marked():
    trajectory = _straight(8.0, 6.0, [(4.0, 0.8)])
    standing = trajectory.time_s[trajectory.speed_mps < ego_model.STANDSTILL_MPS]
    assert 3.9 < standing[0] < standing[-1] < 4.9
    assert ego_model.stood_still(trajectory, standing[0] + 0.1, standing[0] + 0.2)
    assert ego_model.stood_still(trajectory, standing[0] - 0.5, standing[0] + 0.01)
    assert ego_model.stood_still(trajectory, standing[-1] - 0.01, standing[-1] + 0.5)
    assert not ego_model.stood_still(trajectory, standing[0] - 0.5, standing[0] - 0.01)
    assert not ego_model.stood_still(trajectory, standing[-1] + 0.01, standing[-1] + 0.5)


def test_a_simulated_scene_writes_the_flag_for_every_sar_frame(tmp_path):
    from zendar_dataset.format import SceneReader
    from zendar_dataset.format.validate import validate_scene
    from zendar_dataset.sim.generate import synthesize_dataset

    profile = dataclasses.replace(get_profile("tiny"), scene_duration_s=0.5)
    root = synthesize_dataset(tmp_path / "d", profile, n_scenes=1, progress=False)
    path = next((root / "scenes").iterdir())
    assert validate_scene(path) == []
    with SceneReader(path) as scene:
        for sensor in ego_model.RADARS:
            flags = scene.array(f"sar/{sensor}/ego_stopped")[...]
            assert flags.dtype == np.bool_ and flags.shape == scene.timestamps(f"sar/{sensor}").shape
