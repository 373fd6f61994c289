"""Imperfections of the street and the sensor, each against physics or a hand-worked case:
clutter amplitudes against their law (KS test), a facade ghost at the hand-computed mirror point,
a moving car that defocuses and shifts in SAR with its speed ratio (paper §1.1.2), a DOA bias that
grows off boresight, aspect-dependent car RCS, rolling wheels."""

import dataclasses
import math

import numpy as np
import pytest
import scipy.stats

from zendar_dataset.geometry.poses import PoseInterpolator
from zendar_dataset.radar.doa import estimate_azimuth
from zendar_dataset.sim import ego as ego_model
from zendar_dataset.sim.clutter import road_clutter
from zendar_dataset.sim.echoes import car_echoes
from zendar_dataset.sim.imperfections import Imperfections, antenna_errors
from zendar_dataset.sim.profiles import get_profile
from zendar_dataset.sim.radar_model import synthesize_cube
from zendar_dataset.sim.scene import build_scene, simulate_cube, simulate_sar, stream_rng
from zendar_dataset.sim.trajectory import Trajectory
from zendar_dataset.sim.world import COLORS, BoxSet, MovingCar, Road, ScattererSet, World, car_scatterers

NONE = Imperfections.none()


def _straight(start_enu, heading_rad, speed_mps, t0=-2.0, t1=4.0):
    time_s = np.arange(t0, t1, 1e-3)
    direction = np.array([np.cos(heading_rad), np.sin(heading_rad), 0.0])
    position = np.asarray(start_enu, dtype=np.float64) + (time_s - t0)[:, None] * speed_mps * direction
    return Trajectory(time_s, position, np.full(time_s.shape, heading_rad), np.full(time_s.shape, float(speed_mps)))


def _box(center, size, yaw, color):
    return BoxSet(np.array([center], float), np.array([size], float), np.array([yaw], float),
                  np.array([color], np.uint8), np.array([-1], np.int64))


def _sensor_frame(truth, sensor, t):
    rotation, position = ego_model.sensor_poses_enu(truth.ego, sensor, np.array(t))
    return rotation, position


def test_clutter_amplitudes_follow_the_weibull_law_not_rayleigh():
    settings = Imperfections()
    road = Road.from_curvature(-10.0, 200.0, lambda s: np.full_like(s, 1.0 / 80.0))
    clutter = road_clutter(np.random.default_rng(3), road, 0.0, 150.0, (-4.0, 8.0), settings)
    cell_m2 = settings.clutter_spacing_m**2
    amplitude = np.sqrt(clutter.rcs_m2 / (10 ** (settings.clutter_gamma_db / 10) * cell_m2))
    k = settings.clutter_weibull_shape
    # E[a^2] = scale^2 Gamma(1 + 2/k) = 1 (the mean RCS at normal view is gamma times the cell area).
    weibull = scipy.stats.weibull_min(k, scale=1.0 / math.sqrt(math.gamma(1.0 + 2.0 / k)))
    assert scipy.stats.kstest(amplitude, weibull.cdf).pvalue > 0.01
    rayleigh = scipy.stats.rayleigh(scale=1.0 / math.sqrt(2.0))  # also E[a^2] = 1
    assert scipy.stats.kstest(amplitude, rayleigh.cdf).pvalue < 1e-6
    assert np.mean(amplitude**2) == pytest.approx(1.0, rel=0.05)
    assert amplitude.size == pytest.approx(150.0 * 12.0 / cell_m2, rel=0.02)
    # On the ground, between the given lateral offsets of a turning road.
    assert np.all(clutter.position_m[:, 2] == 0.0)
    assert not road_clutter(np.random.default_rng(3), road, 0.0, 150.0, (-4.0, 8.0), NONE).rcs_m2.size


def _facade_world(truth, sensor, t, car_speed_mps, car_in_sensor=(15.0, -6.0), wall_y_m=4.0):
    """A wall parallel to the radar's boresight at ``wall_y_m`` to its left and a car beside it."""
    rotation, position = _sensor_frame(truth, sensor, t)
    yaw = math.atan2(rotation[1, 0], rotation[0, 0])

    def to_world(x, y, z=0.0):
        return rotation @ np.array([x, y, z]) + position * np.array([1, 1, 0])

    wall = _box(to_world(15.0, wall_y_m + 3.0) + [0, 0, 5.0], (30.0, 6.0, 10.0), yaw, COLORS["building"])
    size = np.array([4.5, 1.8, 1.5])
    car_start = to_world(*car_in_sensor) - (t + 2.0) * car_speed_mps * rotation[:, 0] * np.array([1, 1, 0])
    car = MovingCar(1, _straight(car_start, yaw, car_speed_mps), size, car_scatterers(np.random.default_rng(1), size))
    return World(truth.world.road, wall, ScattererSet.empty(), [car]), rotation, position


def test_a_facade_makes_a_ghost_at_the_mirror_position():
    profile = get_profile("tiny")
    truth = build_scene(profile, 0, 0)
    t = 0.5
    world, rotation, position = _facade_world(truth, "front_left", t, 3.0)
    times = np.array([t - 0.01, t, t + 0.01])
    settings = dataclasses.replace(NONE, multipath=True)
    pos, vel, scatterers, ids = car_echoes(world, times, position, settings)
    body, _, body_set, _ = world.moving_scatterers(times)
    n = body.shape[0]
    ghosts = pos[n:]
    assert ghosts.shape[0] == n and np.all(ids[n:] == 1)
    # Mirror by hand in the sensor frame: the wall's face is the plane y = 4 m.
    local = (body - position) @ rotation  # [S, M, 3] sensor frame
    mirrored = local.copy()
    mirrored[..., 1] = 2 * 4.0 - local[..., 1]
    np.testing.assert_allclose((ghosts - position) @ rotation, mirrored, atol=1e-9)
    np.testing.assert_allclose(scatterers.rcs_m2[n:], body_set.rcs_m2 * settings.facade_reflection**4)
    assert car_echoes(world, times, position, NONE)[0].shape[0] == n

    # In a paper-profile cube: energy beyond the car's farthest scatterer, out to its ghost's farthest
    # (|radar - mirror|), only with multipath on.
    paper = get_profile("paper")
    params = ego_model.radar_params(paper)
    car_far = np.linalg.norm(local[:, 1], axis=-1).max()
    ghost_far = np.linalg.norm(mirrored[:, 1], axis=-1).max()
    region = slice(int(np.ceil(car_far / params.range_bin_m)) + 3, int(ghost_far / params.range_bin_m) + 1)
    assert region.stop - region.start >= 5
    truth.world = world
    peak = {}
    for name, effects in (("off", NONE), ("on", settings)):
        cube = simulate_cube(truth, dataclasses.replace(paper, imperfections=effects), "front_left", t,
                             np.random.default_rng(5))
        range_power = np.sum(np.abs(cube) ** 2, axis=2).max(axis=1)  # strongest Doppler cell per range bin
        peak[name] = range_power[region].max()
    noise = np.median(range_power)
    assert peak["off"] < 3 * noise
    assert peak["on"] > 10 * peak["off"]


def _sar_profile():
    # Paper-like SAR (4 cm range resolution would need 2 m apertures and 60 m of image: too slow for a
    # unit test); 5 cm pixels from a 1 m aperture resolve a car's scatterers at 8 m.
    return dataclasses.replace(
        get_profile("tiny"), sar_pixel_m=0.05, sar_bandwidth_hz=299_792_458.0 / (2 * 0.05), sar_aperture_m=1.0,
        sar_coverage_m=11.0, imperfections=NONE,
    )


@pytest.mark.slow
def test_moving_car_defocuses_and_shifts_in_sar_as_its_speed_ratio_grows():
    profile = _sar_profile()
    truth = build_scene(profile, 0, 2)
    t = 0.5
    rotation, position = _sensor_frame(truth, "front_left", t)
    ego_speed = float(np.linalg.norm(truth.ego.velocity_at(np.array(t))))
    assert ego_speed > 3.0
    # The true poses: only the car's motion moves its image (a defocused car's image is a speckle of its
    # 15 scatterers, whose pattern millimetres of navigation error already reshuffle).
    exact = truth.tracklog_truth
    tracklog = PoseInterpolator(exact.timestamp_ns, exact.position_ecef, exact.attitude_wxyz)
    center_sensor = np.array([7.0, 2.0, 0.0])
    center = rotation @ center_sensor + position * np.array([1, 1, 0])
    # An oncoming car: seen 45 deg off the track, it closes in on the radar (which shifts it in azimuth)
    # and moves along the track (which defocuses it), paper 1.1.2.
    heading = float(truth.ego.yaw_at(np.array(t))) + math.pi
    size = np.array([4.5, 1.8, 1.5])
    body = car_scatterers(np.random.default_rng(1), size)
    peaks, brightest = [], []
    for ratio in (0.0, 0.15, 0.4):
        speed = ratio * ego_speed
        start = center - (t + 2.0) * speed * np.array([math.cos(heading), math.sin(heading), 0.0])
        car = MovingCar(1, _straight(start, heading, speed), size, body)
        truth.world = World(truth.world.road, truth.world.static_boxes, ScattererSet.empty(), [car])
        image, grid, _ = simulate_sar(truth, profile, "front_left", t, np.random.default_rng(7), tracklog)
        power = np.abs(image) ** 2
        i, j, _ = grid.world_to_pixel(truth.enu.enu_to_ecef((center + [0, 0, 0.5])[None]))
        # Near the car only: across the track line the image holds its left-right mirror image (a straight
        # track at the image plane's height cannot tell the two sides apart).
        rows, cols = np.indices(power.shape)
        near = np.hypot(rows - i[0], cols - j[0]) * profile.sar_pixel_m < 5.0
        brightest.append(np.array(np.unravel_index(np.argmax(np.where(near, power, 0.0)), power.shape), float))
        peaks.append(power.max())
    # Against the frozen car's image (its brightest part is the near end, not the box centre).
    shifts = [float(np.hypot(*(b - brightest[0]))) * profile.sar_pixel_m for b in brightest]
    # A radial speed v_r moves the image along track by about R v_r / v_ego (R ~ 7.3 m here).
    assert 2 * profile.sar_pixel_m < shifts[1] < shifts[2]
    assert shifts[2] > 6 * profile.sar_pixel_m
    assert peaks[0] > peaks[1] > peaks[2]
    # More than 3 dB lost at 40 % of the ego speed (the Hann taper weights the aperture's middle, where
    # the car's uncompensated phase strays least, so it keeps more peak than uniform weights did).
    assert peaks[2] < peaks[0] / 2


def _doa_bias(errors, angles):
    """(clean, with-error) Bartlett azimuths of a point target at ``angles`` in a paper-profile cube."""
    params = ego_model.radar_params(get_profile("paper"))
    clean, biased = [], []
    for theta in angles:
        point = 30.0 * np.array([np.cos(theta), np.sin(theta), 0.0])
        cube = synthesize_cube(params, np.broadcast_to(point, (1, params.n_chirps, 3)), np.ones(1))
        r, d = np.unravel_index(np.argmax(np.sum(np.abs(cube) ** 2, axis=2)), cube.shape[:2])
        snapshot = cube[r, d]
        clean.append(estimate_azimuth(snapshot[None], params.rx_positions_m, params.wavelength_m)[0])
        biased.append(estimate_azimuth((snapshot * errors)[None], params.rx_positions_m, params.wavelength_m)[0])
    return np.array(clean), np.array(biased)


ANGLES = np.radians([0.0, 20.0, 40.0, 55.0])


def test_doa_bias_of_a_phase_ramp_is_a_constant_shift_in_sine():
    # Hand-worked: receivers at (k - 1.5) lambda / 2 have steering phase -pi sin(theta) (k - 1.5); an
    # extra phase psi k looks like sin(theta) - psi / pi, so the angle error grows like 1 / cos(theta).
    psi = np.radians(10.0)
    clean, biased = _doa_bias(np.exp(1j * psi * np.arange(4)), ANGLES)
    assert np.all(np.abs(clean - ANGLES) < np.radians(0.6))
    np.testing.assert_allclose(np.sin(biased) - np.sin(clean), -psi / np.pi, atol=2e-3)
    bias = np.abs(biased - clean)
    assert np.all(np.diff(bias) > 0) and bias[-1] > 1.5 * bias[0]


@pytest.mark.parametrize("sensor_index", [0, 1])
def test_drawn_antenna_errors_bias_every_angle_by_the_same_shift_in_sine(sensor_index):
    n_rx = ego_model.radar_params(get_profile("paper")).n_antennas
    assert np.all(antenna_errors(sensor_index, n_rx, NONE) == 1)
    errors = antenna_errors(sensor_index, n_rx, Imperfections())
    assert errors[0] == 1 and np.all(np.abs(np.angle(errors[1:])) > 0)
    clean, biased = _doa_bias(errors, ANGLES)
    du = np.sin(biased) - np.sin(clean)
    # Any fixed channel error shifts the Bartlett response in u = sin(theta) rigidly.
    np.testing.assert_allclose(du, du[0], atol=0.15 * abs(du[0]) + 3e-4)
    if abs(du[0]) > 2e-3:
        assert np.abs(biased - clean)[-1] > 1.4 * np.abs(biased - clean)[0]


def test_car_rcs_depends_on_aspect_and_keeps_its_mean():
    size = np.array([4.5, 1.8, 1.5])
    body = car_scatterers(np.random.default_rng(1), size)
    car = MovingCar(1, _straight([0.0, 0.0, 0.0], 0.0, 5.0), size, body)
    world = World(Road.from_curvature(-10.0, 10.0, np.zeros_like), _box([0, 50, 0], (1, 1, 1), 0.0, COLORS["pole"]),
                  ScattererSet.empty(), [car])
    t = np.array([0.0])
    aspects = np.radians(np.arange(0.0, 360.0, 0.5))
    on = dataclasses.replace(NONE, car_aspect=True)
    totals = []
    for aspect in aspects:
        radar = car.trajectory.position_at(t[0]) + 30.0 * np.array([np.cos(aspect), np.sin(aspect), 0.2])
        totals.append(car_echoes(world, t, radar, on)[2].rcs_m2.sum())
        assert car_echoes(world, t, radar, NONE)[2].rcs_m2.sum() == pytest.approx(body.rcs_m2.sum())
    totals = np.array(totals)
    def at(deg):
        return totals[np.argmin(np.abs(aspects - np.radians(deg)))]

    # Measured car signatures peak broadside and head-on, well above the diagonal aspects.
    assert 10 * np.log10(at(90.0) / at(45.0)) > 5.0
    assert 10 * np.log10(at(0.0) / at(45.0)) > 5.0
    assert np.mean(totals) == pytest.approx(body.rcs_m2.sum(), rel=0.05)


def test_wheel_rims_roll_without_slipping():
    size = np.array([4.5, 1.8, 1.5])
    speed = 8.0
    car = MovingCar(1, _straight([0.0, 0.0, 0.0], 0.3, speed), size, car_scatterers(np.random.default_rng(1), size))
    world = World(Road.from_curvature(-10.0, 10.0, np.zeros_like), _box([0, 50, 0], (1, 1, 1), 0.0, COLORS["pole"]),
                  ScattererSet.empty(), [car])
    settings = dataclasses.replace(NONE, wheel_micro_doppler=True)
    radius = settings.wheel_radius_m
    # One full turn of the wheel, finely sampled.
    t = np.linspace(0.0, 2 * np.pi * radius / speed, 400)
    pos, vel, scatterers, ids = car_echoes(world, t, np.array([0.0, 30.0, 0.5]), settings)
    n_body = car.scatterers_body.rcs_m2.size
    rim_pos, rim_vel = pos[n_body:], vel[n_body:]
    assert rim_pos.shape[0] == 8 and np.all(ids == 1)
    ground_speed = np.linalg.norm(rim_vel, axis=-1)
    # Rolling: the top of the rim moves at twice the car's speed, the contact point stands still.
    assert ground_speed.max() == pytest.approx(2 * speed, rel=0.01)
    assert ground_speed.min() < 0.02 * speed
    assert rim_pos[..., 2].min() == pytest.approx(0.0, abs=1e-3)
    # The velocity is the time derivative of the position.
    finite = np.gradient(rim_pos, t, axis=1)
    np.testing.assert_allclose(finite[:, 1:-1], rim_vel[:, 1:-1], atol=0.02 * speed)
    assert car_echoes(world, t, np.array([0.0, 30.0, 0.5]), NONE)[0].shape[0] == n_body


def test_every_effect_can_be_switched_off_for_a_cube():
    profile = dataclasses.replace(get_profile("tiny"), imperfections=NONE)
    truth = build_scene(profile, 0, 0)
    ideal = build_scene(get_profile("tiny"), 0, 0)
    # Clutter is only added when switched on.
    assert ideal.world.static_scatterers.rcs_m2.size > truth.world.static_scatterers.rcs_m2.size
    cube = simulate_cube(truth, profile, "front_left", 0.5, stream_rng(0, 0, "front_left"))
    assert np.isfinite(cube).all()
