"""Labels only where a radar looks: inside a radar's field of view (as the calibration states it) and
never on or behind the ego, checked against the truth trajectories while the ego turns.

The ego drives a left turn (radius 12.5 m, heading from -23 deg to +23 deg); moving cars stand on
two rings around it at every azimuth, so some are ahead, some beside, some behind.  Every label is
recomputed from the car's and the ego's ENU trajectories with the radar mounts and field of view
read from the calibration dict (quaternions turned into yaws here, by hand).
"""

from __future__ import annotations

import numpy as np
import pytest

from zendar_dataset.sim import ego as ego_model
from zendar_dataset.sim.labels import MIN_SPEED_MPS, label_rows, radar_views
from zendar_dataset.sim.profiles import get_profile
from zendar_dataset.sim.trajectory import Trajectory
from zendar_dataset.sim.world import BoxSet, MovingCar, Road, ScattererSet, World, car_scatterers

YAW_START_RAD, YAW_RATE_RADPS, SPEED_MPS = -0.4, 0.8, 10.0
RADIUS_M = SPEED_MPS / YAW_RATE_RADPS
TIMES_S = np.arange(0.05, 1.0, 0.1)
RINGS_M = (18.0, 40.0)
RING_STEP_DEG = 20.0


def _time() -> np.ndarray:
    return np.arange(0.0, 1.0 + 1e-9, 1e-3)


def _ego() -> Trajectory:
    t = _time()
    yaw = YAW_START_RAD + YAW_RATE_RADPS * t
    position = np.zeros((t.size, 3))
    position[:, 0] = RADIUS_M * (np.sin(yaw) - np.sin(YAW_START_RAD))
    position[:, 1] = -RADIUS_M * (np.cos(yaw) - np.cos(YAW_START_RAD))
    return Trajectory(t, position, yaw, np.full(t.size, SPEED_MPS))


def _ring_cars() -> list[MovingCar]:
    """Cars on two rings around the ego's start, each driving tangentially at 4 m/s."""
    rng = np.random.default_rng(3)
    cars, t = [], _time()
    for k, radius in enumerate(RINGS_M):
        for azimuth in np.radians(np.arange(0.0, 360.0, RING_STEP_DEG) + k * RING_STEP_DEG / 2):
            size = np.array([4.5, 1.8, 1.5])
            heading = azimuth + np.pi / 2
            position = np.zeros((t.size, 3))
            position[:, 0] = radius * np.cos(azimuth) + 4.0 * t * np.cos(heading)
            position[:, 1] = radius * np.sin(azimuth) + 4.0 * t * np.sin(heading)
            trajectory = Trajectory(t, position, np.full(t.size, heading), np.full(t.size, 4.0))
            cars.append(MovingCar(len(cars) + 1, trajectory, size, car_scatterers(rng, size)))
    return cars


def _path_is_clear(start: np.ndarray, end: np.ndarray, others: np.ndarray, clearance_m: float = 3.5) -> bool:
    """No point of ``others`` [K, 2] lies within ``clearance_m`` of the segment start-end (ego frame)."""
    direction = end - start
    along = np.clip((others - start) @ direction / (direction @ direction), 0.0, 1.0)
    return bool(np.all(np.linalg.norm(start + along[:, None] * direction - others, axis=1) > clearance_m))


def _yaw_of_wxyz(q) -> float:
    w, x, y, z = q
    return float(np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))


@pytest.fixture(scope="module")
def labelled():
    profile = get_profile("demo")
    ego = _ego()
    cars = _ring_cars()
    empty = BoxSet(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3), np.uint8), np.zeros(0, np.int64))
    world = World(Road.from_curvature(-10.0, 10.0, lambda s: np.zeros_like(s)), empty, ScattererSet.empty(), cars)
    max_range = ego_model.radar_params(profile).max_range_m
    stamps = [1000 + i for i in range(TIMES_S.size)]
    labels = label_rows(world, ego, TIMES_S, {}, stamps, radar_views(max_range))
    return profile, ego, cars, labels, dict(zip(stamps, TIMES_S)), max_range


def _truth_in_ego(ego: Trajectory, car: MovingCar, t: float) -> np.ndarray:
    yaw = float(ego.yaw_at(np.array(t)))
    delta = car.trajectory.position_at(np.array(t))[:2] - ego.position_at(np.array(t))[:2]
    return np.array([np.cos(yaw) * delta[0] + np.sin(yaw) * delta[1], -np.sin(yaw) * delta[0] + np.cos(yaw) * delta[1]])


def _radar_azimuths_deg(profile, point_ego: np.ndarray) -> dict[str, tuple[float, float]]:
    """(azimuth from boresight, range) of an ego-frame point from every radar, from the calibration."""
    sensors = ego_model.calibration(profile)["sensors"]
    out = {}
    for name in ego_model.RADARS:
        mount = np.array(sensors[name]["translation_m"][:2])
        boresight = _yaw_of_wxyz(sensors[name]["rotation_wxyz"])
        delta = point_ego - mount
        azimuth = np.degrees(np.angle(np.exp(1j * (np.arctan2(delta[1], delta[0]) - boresight))))
        out[name] = (float(azimuth), float(np.hypot(*delta)))
    return out


def test_the_calibration_states_each_radars_field_of_view(labelled):
    profile = labelled[0]
    sensors = ego_model.calibration(profile)["sensors"]
    for name in ego_model.RADARS:
        assert 0.0 < sensors[name]["fov_azimuth_deg"] <= 180.0


def test_labels_lie_in_a_radars_field_of_view_and_never_on_or_behind_the_ego(labelled):
    profile, ego, cars, labels, time_of, max_range = labelled
    sensors = ego_model.calibration(profile)["sensors"]
    assert labels["x"].size > 10
    by_track = {car.track_id: car for car in cars}
    for row in range(labels["x"].size):
        t = time_of[int(labels["timestamp_ns"][row])]
        car = by_track[int(labels["track_id"][row])]
        truth = _truth_in_ego(ego, car, t)
        # Labels are the truth in the ego frame of a turning ego (the ego's yaw is not 0 here).
        assert np.allclose([labels["x"][row], labels["y"][row]], truth, atol=1e-6)
        length = ego_model.EGO_SIZE_M[0]
        assert truth[0] > 0.0, f"label behind the front bumper at {truth}"
        assert not (-length <= truth[0] <= 0.0 and abs(truth[1]) <= ego_model.EGO_SIZE_M[1] / 2)
        views = _radar_azimuths_deg(profile, truth)
        assert any(abs(az) <= sensors[n]["fov_azimuth_deg"] / 2 and r < max_range for n, (az, r) in views.items()), views


def test_moving_cars_in_clear_view_are_labelled(labelled):
    """Completeness: a moving car whose centre is well inside a field of view (5 deg from its edges),
    well within range and with no other car near the line of sight (closer than 3.5 m to the path
    from the radar) is labelled."""
    profile, ego, cars, labels, time_of, max_range = labelled
    sensors = ego_model.calibration(profile)["sensors"]
    stamps = {t: s for s, t in time_of.items()}
    labelled_pairs = set(zip(labels["timestamp_ns"].tolist(), labels["track_id"].tolist()))
    expected = 0
    for t in TIMES_S:
        for car in cars:
            truth = _truth_in_ego(ego, car, t)
            if truth[0] <= 1.0 or np.hypot(*car.trajectory.velocity_at(np.array(t))[:2]) <= MIN_SPEED_MPS:
                continue
            views = _radar_azimuths_deg(profile, truth)
            others = np.array([_truth_in_ego(ego, other, t) for other in cars if other is not car])
            clear = [n for n, (az, r) in views.items() if abs(az) <= sensors[n]["fov_azimuth_deg"] / 2 - 5.0
                     and r < max_range - 5.0 and _path_is_clear(np.array(sensors[n]["translation_m"][:2]), truth, others)]
            if clear:
                expected += 1
                assert (stamps[t], car.track_id) in labelled_pairs, f"car {car.track_id} at {truth} (t={t}) unlabelled"
    assert expected > 10
