"""A small two-split dataset whose contents encode where they came from, so the
loader's choices (which cube, which image, which labels) can be checked exactly.

Timeline of scene ``alpha`` (ms after T0; every value an exact integer of ns):
SAR left/right every 100 ms from 0 (10 frames); radar left/right every 50 ms
from -10; camera every 40 ms from +3; lidar every 100 ms from +7; tracklog every
10 ms from -50 to 850 (so the SAR frame at 900 ms has no pose). Cube, image and
lidar values hold the element index (plus 1000 for the right radar).
The IMU drives north at 10 m/s along the prime meridian, on the equator, level.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.datasets import calibration_json
from zendar_dataset.format import DatasetWriter

R, D, A = 8, 4, 2
SAR_H, SAR_W = 6, 5
CAM_H, CAM_W = 4, 6
MS = 1_000_000
T0_NS = 1_300_000_000_000_000_000
A_M = 6378137.0
SPEED_MPS = 10.0
IMU_TRANSLATION_M = [-1.0, 0.0, 0.5]
# At (0°, 0°) heading north, level: IMU forward = +z, right = east = +y, down = -x (ECEF).
ECEF_R_IMU = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])


def calibration() -> dict:
    return calibration_json(n_rx=A, camera_width=CAM_W, camera_height=CAM_H, imu_translation_m=IMU_TRANSLATION_M)


def sar_times(n):
    return T0_NS + 100 * MS * np.arange(n, dtype=np.int64)


def radar_times(n_sar):
    return T0_NS - 10 * MS + 50 * MS * np.arange(2 * n_sar + 1, dtype=np.int64)


def camera_times(n_sar):
    return T0_NS + 3 * MS + 40 * MS * np.arange(int(n_sar * 2.5), dtype=np.int64)


def lidar_times(n_sar):
    return T0_NS + 7 * MS + 100 * MS * np.arange(n_sar, dtype=np.int64)


def tracklog_times():
    return T0_NS - 50 * MS + 10 * MS * np.arange(91, dtype=np.int64)


def imu_position_ecef(timestamp_ns):
    t_s = (np.asarray(timestamp_ns, dtype=np.int64) - T0_NS) / 1e9
    return np.stack([np.full_like(t_s, A_M + 0.5), np.zeros_like(t_s), SPEED_MPS * t_s], axis=-1)


LABELLED = {1: 2, 4: 1}  # SAR frame -> number of cars


def write_scene(writer, n_sar: int, labels: bool) -> None:
    for j, t in enumerate(radar_times(n_sar)):
        writer.append_radar("left", int(t), np.full((R, D, A), j, dtype=np.complex64))
        writer.append_radar("right", int(t), np.full((R, D, A), 1000 + j, dtype=np.complex64))
    for k, t in enumerate(sar_times(n_sar)):
        for sensor in ("left", "right"):
            image = np.full((SAR_H, SAR_W), k + 1j * (sensor == "right"), dtype=np.complex64)
            origin = np.array([A_M, 0.0, 0.0]) + k
            writer.append_sar(sensor, int(t), image, origin, [0.0, 0.04, 0.0], [0.0, 0.0, 0.04], [int(t) - 40 * MS, int(t) + 40 * MS])
    for c, t in enumerate(camera_times(n_sar)):
        writer.append_camera("front", int(t), np.full((CAM_H, CAM_W, 3), c % 256, dtype=np.uint8))
    for l, t in enumerate(lidar_times(n_sar)):
        writer.append_lidar("top", int(t), np.full((l + 1, 4), l, dtype=np.float32))
    tl = tracklog_times()
    writer.write_tracklog(tl, imu_position_ecef(tl), np.tile([np.sqrt(0.5), 0.0, -np.sqrt(0.5), 0.0], (tl.size, 1)))
    if labels:
        rows = [(k, car) for k, n in LABELLED.items() for car in range(n)]
        ts = sar_times(n_sar)
        writer.write_labels(
            {
                "timestamp_ns": np.array([ts[k] for k, _ in rows], dtype=np.int64),
                "x": np.array([10.0 * k + car for k, car in rows]),
                "y": np.array([float(car) for _, car in rows]),
                "length": np.full(len(rows), 4.5),
                "width": np.full(len(rows), 1.8),
                "yaw": np.zeros(len(rows)),
                "vx": np.full(len(rows), 3.0),
                "vy": np.zeros(len(rows)),
                "track_id": np.array([100 * k + car for k, car in rows], dtype=np.int64),
            }
        )


def make_dataset(root, backend: str = "zarr"):
    writer = DatasetWriter(root, "loader-test", backend=backend)
    enu_origin = {"lat_deg": 0.0, "lon_deg": 0.0, "height_m": 0.0}
    for scene_id, n_sar, labels in (("alpha", 10, True), ("beta", 6, True), ("gamma", 4, False)):
        with writer.scene(scene_id, enu_origin=enu_origin, calibration=calibration()) as scene:
            write_scene(scene, n_sar, labels)
    writer.finalize({"train": ["alpha", "beta"], "val": [], "test": ["gamma"]})
    return root


@pytest.fixture(scope="session", params=["zarr", "hdf5"])
def dataset_root(request, tmp_path_factory):
    return make_dataset(tmp_path_factory.mktemp(f"ds-{request.param}"), request.param)


@pytest.fixture(scope="session")
def zarr_root(tmp_path_factory):
    return make_dataset(tmp_path_factory.mktemp("ds-zarr-only"), "zarr")


@pytest.fixture(scope="session")
def hdf5_root(tmp_path_factory):
    return make_dataset(tmp_path_factory.mktemp("ds-hdf5-only"), "hdf5")
