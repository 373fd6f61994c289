"""Occlusion: a car behind a wall gives no radar return, no lidar return and no label; without the
wall it gives all three.  The world is built by hand: the ego (heading 40 deg in ENU, driving) sees
a car 20 m away ahead-left, in the left corner radar's field of view, the wall halfway between them
across the line of sight.  Expected returns come from the geometry, not from the simulator."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from zendar_dataset.radar.fmcw import SPEED_OF_LIGHT_MPS
from zendar_dataset.sim import ego as ego_model
from zendar_dataset.sim.imperfections import Imperfections
from zendar_dataset.sim.labels import label_rows, radar_views
from zendar_dataset.sim.lidar import lidar_sweep
from zendar_dataset.sim.profiles import get_profile
from zendar_dataset.sim.scene import SceneTruth, simulate_cube
from zendar_dataset.sim.trajectory import Trajectory
from zendar_dataset.sim.world import BoxSet, MovingCar, Road, ScattererSet, World, car_scatterers

EGO_YAW_RAD = 0.7
EGO_SPEED_MPS = 5.0
EGO_AT_T_M = np.array([3.0, -2.0, 0.0])  # ENU position of the ego frame's origin at T_S
T_S = 0.5
CAR_EGO_M = np.array([16.0, 12.0])  # car centre in the ego frame at T_S
CAR_SPEED_MPS = 8.0
CAR_SIZE_M = np.array([4.5, 1.8, 1.5])


def _rot(yaw: float) -> np.ndarray:
    return np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])


def _straight(start: np.ndarray, yaw: float, speed: float) -> Trajectory:
    """Constant velocity through ``start`` at T_S."""
    time_s = np.arange(0.0, 1.0 + 1e-9, 1e-3)
    position = np.zeros((time_s.size, 3))
    position[:, :2] = start[:2] + np.outer(time_s - T_S, speed * np.array([np.cos(yaw), np.sin(yaw)]))
    return Trajectory(time_s, position, np.full(time_s.size, yaw), np.full(time_s.size, speed))


def _no_boxes() -> BoxSet:
    return BoxSet(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3), np.uint8), np.zeros(0, np.int64))


def _scene(with_wall: bool) -> SceneTruth:
    ego = _straight(EGO_AT_T_M, EGO_YAW_RAD, EGO_SPEED_MPS)
    car_enu = np.zeros(3)
    car_enu[:2] = EGO_AT_T_M[:2] + _rot(EGO_YAW_RAD) @ CAR_EGO_M
    # The car drives towards the ego's rear (against its heading), so it has a large radial speed.
    car = MovingCar(1, _straight(car_enu, EGO_YAW_RAD + np.pi, CAR_SPEED_MPS), CAR_SIZE_M,
                    car_scatterers(np.random.default_rng(5), CAR_SIZE_M))
    boxes = _no_boxes()
    if with_wall:
        line_of_sight = np.arctan2(CAR_EGO_M[1], CAR_EGO_M[0])
        wall_ego = 0.5 * CAR_EGO_M
        wall_enu = EGO_AT_T_M[:2] + _rot(EGO_YAW_RAD) @ wall_ego
        boxes = BoxSet(np.array([[wall_enu[0], wall_enu[1], 1.5]]), np.array([[8.0, 0.3, 3.0]]),
                       np.array([EGO_YAW_RAD + line_of_sight + np.pi / 2]), np.array([[170, 150, 130]], np.uint8),
                       np.array([-1]))
    road = Road.from_curvature(-10.0, 10.0, lambda s: np.zeros_like(s))
    world = World(road, boxes, ScattererSet.empty(), [car])
    return SceneTruth(world, ego, None, None, None, 0)


def _quiet_profile():
    """The demo radar with every optional imperfection off: the car is the only scatterer."""
    off = {f.name: False for f in dataclasses.fields(Imperfections) if f.type in (bool, "bool")}
    return dataclasses.replace(get_profile("demo"), imperfections=Imperfections(**off))


def _car_range_m(sensor: str) -> float:
    mount = ego_model.EGO_T_SENSOR[sensor].translation
    return float(np.hypot(*(CAR_EGO_M - mount[:2])))


def _peak_over_median_db(cube: np.ndarray, range_bin_m: float, centre_m: float) -> float:
    """Strongest cell within +-4 m of ``centre_m`` (all Doppler bins) over the cube's median cell power."""
    power = np.sum(np.abs(cube) ** 2, axis=-1)
    lo, hi = int((centre_m - 4.0) / range_bin_m), int((centre_m + 4.0) / range_bin_m) + 1
    return float(10 * np.log10(power[lo:hi].max() / np.median(power)))


@pytest.fixture(scope="module")
def profile():
    return _quiet_profile()


def test_a_car_behind_a_wall_returns_nothing_to_the_radar_and_returns_without_it(profile):
    params = ego_model.radar_params(profile)
    assert abs(params.range_bin_m - SPEED_OF_LIGHT_MPS / (2 * params.bandwidth_hz)) < 1e-9
    centre = _car_range_m("front_left")
    seen = simulate_cube(_scene(False), profile, "front_left", T_S, np.random.default_rng(1))
    hidden = simulate_cube(_scene(True), profile, "front_left", T_S, np.random.default_rng(1))
    # A 1-3 m^2 car at 20 m is tens of dB over the noise; behind the wall only noise is left there
    # (the largest of a few hundred noise cells is ~8 dB over their median).
    assert _peak_over_median_db(seen, params.range_bin_m, centre) > 30.0
    assert _peak_over_median_db(hidden, params.range_bin_m, centre) < 13.0


def test_the_lidar_is_blocked_by_the_same_wall():
    counts = {}
    for with_wall in (False, True):
        truth = _scene(with_wall)
        rotation, position = ego_model.sensor_poses_enu(truth.ego, ego_model.LIDAR, np.array(T_S))
        boxes = truth.world.boxes_at(T_S)
        _points, hit = lidar_sweep(np.random.default_rng(2), rotation, position, boxes, 0.4)
        counts[with_wall] = int(np.count_nonzero(boxes.track_id[hit[hit >= 0]] == 1))
    assert counts[False] >= 10
    assert counts[True] == 0


def test_the_car_is_labelled_only_when_the_radar_can_see_it(profile):
    views = radar_views(ego_model.radar_params(profile).max_range_m)
    for with_wall, expected in ((False, 1), (True, 0)):
        truth = _scene(with_wall)
        labels = label_rows(truth.world, truth.ego, np.array([T_S]), {}, [123], views)
        assert labels["x"].size == expected
        if expected:
            # The label is the car in the ego frame (rotated by the ego's 40 deg heading).
            assert np.allclose([labels["x"][0], labels["y"][0]], CAR_EGO_M, atol=1e-6)
            assert labels["num_radar_scatterers"][0] >= 3
            # Its velocity over ground points against the ego's heading.
            assert np.allclose([labels["vx"][0], labels["vy"][0]], [-CAR_SPEED_MPS, 0.0], atol=1e-6)
