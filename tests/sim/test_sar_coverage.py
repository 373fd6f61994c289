"""SAR that covers the street: each radar's image holds its field of view out to 60 m and the lane
ahead, and is formed from its own wide-band waveform (paper §1.1.1: up to 4 GHz, ~4 cm)."""

import math

import numpy as np
import pytest

from zendar_dataset.errors import ZendarFormatError
from zendar_dataset.format.calibration import Calibration
from zendar_dataset.geometry.poses import PoseInterpolator
from zendar_dataset.radar.fmcw import SPEED_OF_LIGHT_MPS
from zendar_dataset.sar.grid import ImageGrid
from zendar_dataset.sim import ego as ego_model
from zendar_dataset.sim.profiles import PROFILES, get_profile
from zendar_dataset.sim.radar_model import synthesize_range_profiles
from zendar_dataset.sim.sar_formation import form_image, sar_waveform
from zendar_dataset.sim.scene import build_scene, sar_footprint, simulate_sar, stream_rng
from zendar_dataset.sim.trajectory import follow_road, speed_profile
from zendar_dataset.sim.world import Road

LANE_HALF_WIDTH_M = 1.75


def _must_see_ego(calibration_entry, reach_m=60.0):
    """Points (ego frame, radar height) the image must hold, from the calibration alone:
    the field-of-view sector out to ``reach_m`` and the ego lane ahead to ``reach_m``."""
    w, x, y, z = calibration_entry["rotation_wxyz"]
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    half_fov = math.radians(calibration_entry["fov_azimuth_deg"]) / 2
    radar = np.array(calibration_entry["translation_m"])
    points = []
    for angle in np.linspace(yaw - half_fov, yaw + half_fov, 25):
        for r in (5.0, 30.0, reach_m):
            points.append(radar + r * np.array([math.cos(angle), math.sin(angle), 0.0]))
    for ahead in np.linspace(0.0, reach_m, 13):
        for lateral in (-LANE_HALF_WIDTH_M, 0.0, LANE_HALF_WIDTH_M):
            points.append(np.array([ahead, lateral, radar[2]]))
    return np.array(points)


@pytest.mark.parametrize("name", sorted(PROFILES))
@pytest.mark.parametrize("sensor", ego_model.RADARS)
def test_footprint_holds_the_field_of_view_and_the_lane_ahead_to_60_m(name, sensor):
    profile = get_profile(name)
    entry = ego_model.calibration(profile)["sensors"][sensor]
    geometry = sar_footprint(profile, sensor)
    grid = ImageGrid.axis_aligned(geometry.center_ego, [1.0, 0, 0], [0, 1.0, 0], geometry.pixel_m, geometry.shape)
    i, j, height = grid.world_to_pixel(_must_see_ego(entry))
    assert np.all((i >= -0.5) & (i <= geometry.shape[0] - 0.5)), name
    assert np.all((j >= -0.5) & (j <= geometry.shape[1] - 0.5)), name
    np.testing.assert_allclose(height, 0.0, atol=1e-9)
    assert geometry.pixel_m == profile.sar_pixel_m
    # The smallest such rectangle: no side is more than a few pixels longer than the sector needs.
    extent = (np.array(geometry.shape) - 1) * geometry.pixel_m
    assert np.all(extent < profile.sar_coverage_m * (1 + math.sin(math.radians(15.0))) + 2.0)


def test_simulated_image_lies_where_the_footprint_says_in_a_turning_scene():
    profile = get_profile("tiny")
    truth = build_scene(profile, 1, 0)
    # Drive the ego round a 30 m radius bend already 40 deg in, so a footprint not rotated with it would miss.
    road = Road.from_curvature(-60.0, 100.0, lambda s: np.full_like(s, 1.0 / 30.0))
    time_s, speed = speed_profile(4.0, 9.0, [])
    truth.ego = follow_road(road, time_s - 1.5, speed, 21.0)
    truth.tracklog_truth, truth.tracklog_written = ego_model.make_tracklogs(
        truth.ego, truth.enu, truth.start_ns, -1.0, 2.0, np.random.default_rng(0)
    )
    index = 0
    assert abs(truth.ego.yaw_at(np.array(0.55))) > math.radians(40.0)
    t = 0.55
    written = truth.tracklog_written
    tracklog = PoseInterpolator(written.timestamp_ns, written.position_ecef, written.attitude_wxyz)
    for sensor in ego_model.RADARS:
        image, grid_ecef, _ = simulate_sar(truth, profile, sensor, t, stream_rng(1, index, f"sar_{sensor}"), tracklog)
        assert image.shape == sar_footprint(profile, sensor).shape
        entry = ego_model.calibration(profile)["sensors"][sensor]
        rotation, translation = ego_model.enu_T_ego(truth.ego, np.array(t))
        points_enu = _must_see_ego(entry) @ rotation.T + translation
        i, j, height = grid_ecef.world_to_pixel(truth.enu.enu_to_ecef(points_enu))
        # The image is placed from the written (biased) tracklog: a few cm of slack.
        assert np.all((i >= -0.7) & (i <= image.shape[0] - 0.3))
        assert np.all((j >= -0.7) & (j <= image.shape[1] - 0.3))
        assert np.all(np.abs(height) < 0.2)


def test_sar_bandwidth_is_its_own_calibration_field_and_the_cube_keeps_its_bins():
    paper = get_profile("paper")
    calibration = ego_model.calibration(paper)
    for sensor in ego_model.RADARS:
        entry = calibration["sensors"][sensor]
        assert entry["sar_bandwidth_hz"] == paper.sar_bandwidth_hz
        assert 3.5e9 <= entry["sar_bandwidth_hz"] <= 4.0e9
        assert SPEED_OF_LIGHT_MPS / (2 * entry["sar_bandwidth_hz"]) == pytest.approx(0.04, abs=0.003)
        assert entry["range_bin_m"] == pytest.approx(0.18, rel=0.01)
        assert entry["n_samples"] == 512
    # The format keeps the field through a JSON round trip, and files without it stay valid.
    again = Calibration.from_json(Calibration.from_json(calibration).to_json()).to_json()
    assert again["sensors"]["front_left"]["sar_bandwidth_hz"] == paper.sar_bandwidth_hz
    del calibration["sensors"]["front_left"]["sar_bandwidth_hz"]
    assert "sar_bandwidth_hz" not in Calibration.from_json(calibration).to_json()["sensors"]["front_left"]


def test_paper_sar_resolves_4_cm_in_range():
    paper = get_profile("paper")
    params = sar_waveform(ego_model.radar_params(paper), paper.sar_bandwidth_hz, 30.0)
    assert params.range_bin_m == pytest.approx(SPEED_OF_LIGHT_MPS / (2 * paper.sar_bandwidth_hz))
    assert params.max_range_m >= 30.0
    # A side-looking 0.2 m aperture, a point 10 m away: cut the image along the range axis.
    spacing = params.wavelength_m / 4
    x = np.arange(-0.1, 0.1 + 1e-9, spacing)
    radar = np.stack([x, np.zeros_like(x), np.zeros_like(x)], axis=1)
    world_r_sensor = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # boresight along +y
    target = np.array([0.0, 10.0, 0.0])
    local = ((target - radar) @ world_r_sensor)[:, None, :]
    velocity = np.broadcast_to(np.array([-10.0, 0.0, 0.0]) @ world_r_sensor, local.shape)
    receiver = params.rx_positions_m[0]
    profiles = synthesize_range_profiles(params, local, velocity, np.ones((x.shape[0], 1)), receiver)
    pixel = 0.005
    grid = ImageGrid.axis_aligned(target, [1.0, 0, 0], [0, 1.0, 0], (0.02, pixel), (5, 81))
    image = np.abs(form_image(params, profiles, radar + world_r_sensor @ (receiver / 2), grid))
    cut = image[2] ** 2
    above = np.flatnonzero(cut > cut.max() / 2)
    width_m = (above[-1] - above[0] + 1) * pixel
    # Hann window: 3-dB width 1.44 range bins of c / (2 B) = 4 cm (0.18 m bins would give 26 cm).
    assert width_m == pytest.approx(1.44 * SPEED_OF_LIGHT_MPS / (2 * paper.sar_bandwidth_hz), rel=0.2)
    assert abs(int(np.argmax(cut)) - 40) <= 1


def test_the_azimuth_window_is_recorded_in_the_calibration_and_optional_in_the_format():
    calibration = ego_model.calibration(get_profile("demo"))
    for sensor in ego_model.RADARS:
        assert calibration["sensors"][sensor]["sar_azimuth_window"] == "hann"
    again = Calibration.from_json(Calibration.from_json(calibration).to_json()).to_json()
    assert again["sensors"]["front_right"]["sar_azimuth_window"] == "hann"
    del calibration["sensors"]["front_right"]["sar_azimuth_window"]
    assert "sar_azimuth_window" not in Calibration.from_json(calibration).to_json()["sensors"]["front_right"]
    calibration["sensors"]["front_right"]["sar_azimuth_window"] = 3
    with pytest.raises(ZendarFormatError, match="sar_azimuth_window"):
        Calibration.from_json(calibration)
