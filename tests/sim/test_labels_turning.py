"""Labels of a scene whose ego turns through 46°, checked against the truth trajectories.

The ego of a simulated scene follows a straight road at the start of the drive, so its yaw is
close to 0 and a label written without rotating into the ego frame would look right. Here the
ego drives a circle (radius 12.5 m, 10 m/s, heading from -23° to +23° over the 1 s scene) and
every label is recomputed by hand from the car's and the ego's true ENU trajectories.
"""

from __future__ import annotations

import numpy as np
import pytest

from zendar_dataset.format import DatasetWriter, open_dataset
from zendar_dataset.sim import ego as ego_model
from zendar_dataset.sim import scene as scene_module
from zendar_dataset.sim.profiles import get_profile
from zendar_dataset.sim.scene import build_scene, write_scene
from zendar_dataset.sim.trajectory import Trajectory

YAW_START_RAD = -0.4
YAW_RATE_RADPS = 0.8
SPEED_MPS = 10.0
RADIUS_M = SPEED_MPS / YAW_RATE_RADPS


def _circle(time_s: np.ndarray) -> Trajectory:
    """A left turn through the ENU origin at t = 0, heading YAW_START_RAD there."""
    yaw = YAW_START_RAD + YAW_RATE_RADPS * time_s
    center = -RADIUS_M * np.array([np.sin(YAW_START_RAD), -np.cos(YAW_START_RAD)])
    position = np.zeros((time_s.size, 3))
    position[:, 0] = center[0] + RADIUS_M * np.sin(yaw)
    position[:, 1] = center[1] - RADIUS_M * np.cos(yaw)
    return Trajectory(time_s, position, yaw, np.full(time_s.size, SPEED_MPS))


@pytest.fixture(scope="module")
def turning_scene(tmp_path_factory):
    profile = get_profile("tiny")
    with pytest.MonkeyPatch.context() as patch:
        # build_scene draws the ego's drive with follow_road; everything else (traffic kept clear
        # of the ego, tracklogs) is derived from the ego it returns.
        patch.setattr(scene_module, "follow_road", lambda road, time_s, speed, s0: _circle(np.asarray(time_s)))
        truth = build_scene(profile, seed=4, scene_index=0)
    root = tmp_path_factory.mktemp("turning")
    writer = DatasetWriter(root, "turning", backend="zarr")
    origin = {"lat_deg": truth.enu.lat_deg, "lon_deg": truth.enu.lon_deg, "height_m": truth.enu.height_m}
    with writer.scene("turn", enu_origin=origin, calibration=ego_model.calibration(profile)) as scene:
        write_scene(scene, truth, profile, 4, 0)
    writer.finalize({"train": ["turn"], "val": [], "test": []})
    labels = open_dataset(root).open_scene("turn").labels()
    return truth, labels


def test_the_ego_turns_and_cars_are_labelled_while_it_does(turning_scene):
    truth, labels = turning_scene
    t_s = (labels["timestamp_ns"] - truth.start_ns) / 1e9
    yaw = truth.ego.yaw_at(t_s)
    assert np.degrees(truth.ego.yaw_at(np.array([1.0]))[0] - truth.ego.yaw_at(np.array([0.0]))[0]) >= 30
    assert labels["x"].size >= 5
    # Labels early and late in the turn, where omitting the rotation moves a car by metres.
    assert np.degrees(yaw.min()) <= -10 and np.degrees(yaw.max()) >= 10


def test_every_label_is_its_truth_car_in_the_ego_frame(turning_scene):
    truth, labels = turning_scene
    cars = {car.track_id: car for car in truth.world.cars}
    assert set(labels["track_id"].tolist()) <= set(cars)
    for row in range(labels["x"].size):
        t = np.array([(labels["timestamp_ns"][row] - truth.start_ns) / 1e9])
        car = cars[int(labels["track_id"][row])]
        # ENU -> ego by hand: subtract the ego's position, rotate by minus its yaw about up.
        ego_yaw = float(truth.ego.yaw_at(t)[0])
        c, s = np.cos(ego_yaw), np.sin(ego_yaw)
        ego_R_enu = np.array([[c, s], [-s, c]])
        offset = car.trajectory.position_at(t)[0, :2] - truth.ego.position_at(t)[0, :2]
        expected_xy = ego_R_enu @ offset
        car_yaw = float(car.trajectory.yaw_at(t)[0])
        expected_v = ego_R_enu @ car.trajectory.velocity_at(t)[0, :2]  # over ground, in the ego's axes
        np.testing.assert_allclose([labels["x"][row], labels["y"][row]], expected_xy, atol=1e-6, err_msg=f"row {row}")
        np.testing.assert_allclose([labels["vx"][row], labels["vy"][row]], expected_v, atol=1e-6, err_msg=f"row {row}")
        relative_yaw = np.angle(np.exp(1j * (labels["yaw"][row] - (car_yaw - ego_yaw))))
        assert abs(relative_yaw) < 1e-9, row
        assert expected_xy[0] > 0  # labelled cars are ahead of the ego
