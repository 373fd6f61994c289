import numpy as np
import pytest

from zendar_dataset.errors import ZendarError
from zendar_dataset.geometry import SE3, LocalENU, PoseInterpolator, matrix_to_quat_wxyz
from zendar_dataset.geometry.frames import EgoPoses, ecef_to_sar_pixel, ego_T_sensor, sar_pixel_to_ecef

A_M = 6378137.0


def test_imu_frd_to_ego_flu_hand_worked():
    # Vehicle on the equator at the prime meridian, level, heading north.
    # There ENU east = ECEF +y, north = +z, up = +x.
    # IMU axes (forward, right, down) in ECEF: forward = +z, right = east = +y, down = -x.
    ecef_R_imu = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])
    imu_position_ecef = np.array([A_M + 0.5, 0.0, 1.0])
    # The IMU sits 1 m behind the front bumper, 0.5 m above ground, axes FRD:
    # ego_R_imu = diag(1, -1, -1), ego_t_imu = (-1, 0, 0.5).
    calibration = {"rotation_wxyz": [0.0, 1.0, 0.0, 0.0], "translation_m": [-1.0, 0.0, 0.5]}
    ego_T_imu = ego_T_sensor(calibration)
    np.testing.assert_allclose(ego_T_imu.rotation, np.diag([1.0, -1.0, -1.0]), atol=1e-15)
    t_ns = np.array([0, 1_000_000_000], dtype=np.int64)
    tracklog = PoseInterpolator(
        t_ns, np.stack([imu_position_ecef] * 2), np.stack([matrix_to_quat_wxyz(ecef_R_imu)] * 2)
    )
    poses = EgoPoses(tracklog, ego_T_imu, LocalENU(0.0, 0.0, 0.0))
    ecef_T_ego = poses.ecef_T_ego(500_000_000)
    # Ego origin: 1 m ahead (north, +z) of the IMU and 0.5 m lower (-x): (A, 0, 2).
    np.testing.assert_allclose(ecef_T_ego.translation, [A_M, 0.0, 2.0], atol=1e-9)
    # Ego axes in ECEF: forward = +z, left = west = -y, up = +x.
    np.testing.assert_allclose(ecef_T_ego.rotation, [[0, 0, 1], [0, -1, 0], [1, 0, 0]], atol=1e-12)
    # A point 10 m ahead, 2 m left, 3 m up of the ego origin.
    np.testing.assert_allclose(poses.ego_to_ecef([10.0, 2.0, 3.0], 0), [A_M + 3.0, -2.0, 12.0], atol=1e-9)
    # ...is 2 m west, 12 m north, 3 m up in ENU.
    np.testing.assert_allclose(poses.ego_to_enu([10.0, 2.0, 3.0], 0), [-2.0, 12.0, 3.0], atol=1e-6)
    np.testing.assert_allclose(poses.enu_to_ego([-2.0, 12.0, 3.0], 0), [10.0, 2.0, 3.0], atol=1e-6)
    np.testing.assert_allclose(poses.ecef_to_ego([A_M + 3.0, -2.0, 12.0], 0), [10.0, 2.0, 3.0], atol=1e-9)
    # A sensor yawed 90° left, mounted at the front-left corner: its boresight is west.
    ego_T_radar = SE3.from_wxyz([np.sqrt(0.5), 0, 0, np.sqrt(0.5)], [0.0, 0.9, 0.5])
    np.testing.assert_allclose(
        poses.sensor_to_ecef([5.0, 0.0, 0.0], ego_T_radar, 0), [A_M + 0.5, -5.9, 2.0], atol=1e-9
    )
    np.testing.assert_allclose(
        poses.ecef_to_sensor([A_M + 0.5, -5.9, 2.0], ego_T_radar, 0), [5.0, 0.0, 0.0], atol=1e-9
    )


def test_enu_T_ego_agrees_with_pyproj_points():
    enu = LocalENU(48.1, 11.6, 520.0)
    rng = np.random.default_rng(4)
    ecef_R_imu = SE3.from_wxyz(rng.normal(size=4), [0, 0, 0]).rotation
    imu_position_ecef = enu.enu_to_ecef([120.0, -40.0, 1.5])
    tracklog = PoseInterpolator(
        np.array([0, 10], dtype=np.int64),
        np.stack([imu_position_ecef] * 2),
        np.stack([matrix_to_quat_wxyz(ecef_R_imu)] * 2),
    )
    poses = EgoPoses(tracklog, SE3.from_wxyz([0, 1, 0, 0], [-1.2, 0.1, 0.4]), enu)
    points_ego = rng.uniform(-50, 50, size=(20, 3))
    via_ecef = enu.ecef_to_enu(poses.ego_to_ecef(points_ego, 5))
    np.testing.assert_allclose(poses.ego_to_enu(points_ego, 5), via_ecef, atol=1e-6)


def test_ego_T_sensor_needs_both_fields():
    with pytest.raises(ZendarError, match="rotation_wxyz"):
        ego_T_sensor({"translation_m": [0, 0, 0]})


def test_sar_pixel_round_trip_and_plane_distance():
    origin = np.array([4_000_000.0, 600_000.0, 4_900_000.0])
    di = np.array([0.04, 0.0, 0.0])
    dj = np.array([0.0, 0.028284271247461905, 0.028284271247461905])  # 4 cm, 45° in y-z
    np.testing.assert_allclose(sar_pixel_to_ecef(10, 20, origin, di, dj), origin + 10 * di + 20 * dj)
    i = np.array([[0.0, 12.5], [511.0, 3.25]])
    j = np.array([[0.0, 7.0], [100.0, 999.5]])
    points = sar_pixel_to_ecef(i, j, origin, di, dj)
    assert points.shape == (2, 2, 3)
    normal = np.cross(di, dj) / np.linalg.norm(np.cross(di, dj))
    i2, j2, distance_m = ecef_to_sar_pixel(points + 0.7 * normal, origin, di, dj)
    np.testing.assert_allclose(i2, i, atol=1e-6)
    np.testing.assert_allclose(j2, j, atol=1e-6)
    np.testing.assert_allclose(distance_m, 0.7, atol=1e-6)
    with pytest.raises(ValueError, match="parallel"):
        ecef_to_sar_pixel(points, origin, di, 2 * di)
