"""Lidar, camera and tracklog models against geometry worked by hand."""

import numpy as np

from zendar_dataset.geometry.geodesy import LocalENU
from zendar_dataset.geometry.quaternion import quat_wxyz_to_matrix
from zendar_dataset.sim import camera
from zendar_dataset.sim.ego import EGO_T_SENSOR, IMU, TracklogNoise, make_tracklogs
from zendar_dataset.sim.lidar import lidar_sweep
from zendar_dataset.sim.raycast import GROUND
from zendar_dataset.sim.trajectory import Trajectory
from zendar_dataset.sim.world import BoxSet


def _boxes():
    return BoxSet(
        center_enu=np.array([[10.0, 0.0, 1.0], [0.0, 8.0, 2.0]]),
        size_m=np.array([[4.0, 2.0, 2.0], [2.0, 2.0, 4.0]]),
        yaw_rad=np.array([0.3, 0.0]),
        color=np.array([[255, 0, 0], [0, 255, 0]], np.uint8),
        track_id=np.array([1, -1]),
    )


def test_lidar_returns_lie_on_box_surfaces_and_the_ground():
    boxes = _boxes()
    origin = np.array([0.0, 0.0, 1.5])
    points, hit = lidar_sweep(np.random.default_rng(0), np.eye(3), origin, boxes, 1.0)
    world = points[:, :3].astype(np.float64) + origin
    assert np.count_nonzero(hit == 0) > 10 and np.count_nonzero(hit == 1) > 10
    for b in (0, 1):
        c, s = np.cos(boxes.yaw_rad[b]), np.sin(boxes.yaw_rad[b])
        local = world[hit == b] - boxes.center_enu[b]
        local[:, :2] = local[:, :2] @ np.array([[c, -s], [s, c]])
        # Distance outside/inside the box surface: the largest normalised coordinate is 1 (+- range noise).
        excess = np.max(np.abs(local) - boxes.size_m[b] / 2, axis=1)
        assert np.all(np.abs(excess) < 0.1)
    assert np.all(np.abs(world[hit == GROUND, 2]) < 0.1)
    assert np.all((points[:, 3] >= 0) & (points[:, 3] <= 255))


def test_camera_renders_a_known_point_on_its_projected_pixel():
    k = np.array([[100.0, 0.0, 79.5], [0.0, 100.0, 59.5], [0.0, 0.0, 1.0]])
    distortion = np.array([-0.08, 0.01, 0.001, -0.002, 0.0])
    rays = camera.pixel_rays(k, distortion, 120, 160)
    # Rays reproject onto their own pixels through the forward model.
    sample = rays[[10, 60, 100], [20, 80, 150]]
    assert np.allclose(camera.project(sample, k, distortion), [[20, 10], [80, 60], [150, 100]], atol=1e-6)
    # A small red box seen by a camera at the ENU origin looking east (optical z = east).
    enu_r_camera = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    position = np.array([0.0, 0.0, 2.0])
    target = np.array([10.0, 1.5, 2.5])
    boxes = BoxSet(target[None], np.array([[0.1, 0.1, 0.1]]), np.zeros(1), np.array([[255, 0, 0]], np.uint8), np.array([-1]))
    image = camera.render(rays, enu_r_camera, position, boxes)
    red = np.argwhere((image[..., 0] > 100) & (image[..., 1] < 50))
    expected_uv = camera.project((target - position) @ enu_r_camera, k, distortion)
    assert red.size
    assert np.abs(red.mean(axis=0)[::-1] - expected_uv).max() < 1.0


def test_tracklog_round_trips_to_enu_through_pyproj():
    t = np.arange(0.0, 2.0, 0.001)
    trajectory = Trajectory(t, np.stack([5.0 * t, 2.0 * t, 0 * t], axis=1), np.full_like(t, 0.4), np.full_like(t, 5.4))
    enu = LocalENU(37.77, -122.42, 10.0)
    truth, noisy = make_tracklogs(trajectory, enu, 10**18, 0.0, 1.0, np.random.default_rng(0), TracklogNoise())
    assert truth.timestamp_ns[1] - truth.timestamp_ns[0] == 10_000_000  # 100 Hz
    seconds = (truth.timestamp_ns - 10**18) / 1e9
    imu = EGO_T_SENSOR[IMU]
    yaw = np.array([[np.cos(0.4), -np.sin(0.4), 0], [np.sin(0.4), np.cos(0.4), 0], [0, 0, 1]])
    expected = trajectory.position_at(seconds) + imu.translation @ yaw.T
    assert np.allclose(enu.ecef_to_enu(truth.position_ecef), expected, atol=1e-6)
    enu_r_imu = enu.ecef_R_enu.T @ quat_wxyz_to_matrix(truth.attitude_wxyz)
    assert np.allclose(enu_r_imu, yaw @ imu.rotation, atol=1e-9)
    # The written tracklog is off by centimetres, not metres, and differs from the truth.
    error = np.linalg.norm(noisy.position_ecef - truth.position_ecef, axis=1)
    assert 0 < error.max() < 0.3
