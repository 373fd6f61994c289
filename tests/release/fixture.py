"""A small synthetic release scene with known geometry, written with the tests' own encoder.

The vehicle drives a left-turning arc near San Francisco; two radars (serials
``1739000J1Q`` on the left, ``1739000J2R`` on the right) image strips beside
it.  Each SAR frame has one bright pixel at a known (i, j); a lidar point and a
detection sit at that pixel's ECEF position, so an importer that gets the
image model, the pixel order or the frames wrong misplaces them.
"""

from __future__ import annotations

import pathlib
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from tests.release import encoder as enc

LAT_DEG, LON_DEG, HEIGHT_M = 37.7749, -122.4194, 12.0
WGS84_A = 6378137.0
WGS84_E2 = 6.69437999014e-3
T0_S = 1_264_000_000.123456789  # GPS seconds; the double nearest this is what gets written
SERIALS = {"1739000J1Q": "left", "1739000J2R": "right"}
ROWS, COLS = 40, 24  # rows != cols, so a transposed reading misplaces pixels
PIXEL_M = 0.04


def geodetic_to_ecef(lat_deg: float, lon_deg: float, h: float) -> np.ndarray:
    lat, lon = np.radians(lat_deg), np.radians(lon_deg)
    n = WGS84_A / np.sqrt(1 - WGS84_E2 * np.sin(lat) ** 2)
    return np.array([(n + h) * np.cos(lat) * np.cos(lon), (n + h) * np.cos(lat) * np.sin(lon), (n * (1 - WGS84_E2) + h) * np.sin(lat)])


def ecef_R_enu(lat_deg: float, lon_deg: float) -> np.ndarray:
    lat, lon = np.radians(lat_deg), np.radians(lon_deg)
    east = [-np.sin(lon), np.cos(lon), 0.0]
    north = [-np.sin(lat) * np.cos(lon), -np.sin(lat) * np.sin(lon), np.cos(lat)]
    up = [np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)]
    return np.column_stack([east, north, up])


ORIGIN_ECEF = geodetic_to_ecef(LAT_DEG, LON_DEG, HEIGHT_M)
R_ECEF_ENU = ecef_R_enu(LAT_DEG, LON_DEG)


def enu_to_ecef(p_enu: np.ndarray) -> np.ndarray:
    return ORIGIN_ECEF + np.asarray(p_enu) @ R_ECEF_ENU.T


def vehicle(t_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ENU position, IMU(FRD)->ECEF rotation matrix and heading (rad) at ``t_s`` seconds after T0."""
    yaw = 0.3 + 0.25 * t_s  # turning left
    radius = 8.0 / 0.25  # 8 m/s
    p_enu = np.array([radius * np.sin(yaw) - radius * np.sin(0.3), -radius * np.cos(yaw) + radius * np.cos(0.3), 0.0])
    forward = np.array([np.cos(yaw), np.sin(yaw), 0.0])
    right = np.array([np.sin(yaw), -np.cos(yaw), 0.0])
    down = np.array([0.0, 0.0, -1.0])
    R_enu_imu = np.column_stack([forward, right, down])
    return p_enu, R_ECEF_ENU @ R_enu_imu, yaw


def wxyz(matrix: np.ndarray) -> np.ndarray:
    x, y, z, w = Rotation.from_matrix(matrix).as_quat()
    return np.array([w, x, y, z])


@dataclass
class SarTruth:
    """What one written SAR frame holds: time, model and its bright pixel."""

    timestamp_s: float
    origin_ecef: np.ndarray
    di_ecef: np.ndarray
    dj_ecef: np.ndarray
    bright_ij: tuple[int, int]
    target_ecef: np.ndarray


@dataclass
class Truth:
    sar: dict[str, list[SarTruth]] = field(default_factory=dict)  # by side
    tracklog_s: list[float] = field(default_factory=list)
    n_detections: dict[str, int] = field(default_factory=dict)


def sar_frame(side: str, t_s: float, k: int) -> SarTruth:
    p_enu, R_ecef_imu, yaw = vehicle(t_s)
    forward = np.array([np.cos(yaw), np.sin(yaw), 0.0])
    left = np.array([-np.sin(yaw), np.cos(yaw), 0.0])
    outward = left if side == "left" else -left
    di_enu = PIXEL_M * forward
    dj_enu = PIXEL_M * outward
    centre = p_enu + 10.0 * outward
    origin_enu = centre - ROWS / 2 * di_enu - COLS / 2 * dj_enu
    i, j = 5 + (3 * k) % 30, 2 + (5 * k) % 20
    target_enu = origin_enu + i * di_enu + j * dj_enu
    return SarTruth(
        T0_S + t_s,
        enu_to_ecef(origin_enu),
        R_ECEF_ENU @ di_enu,
        R_ECEF_ENU @ dj_enu,
        (i, j),
        enu_to_ecef(target_enu),
    )


def _flat(image: np.ndarray, row_major: bool) -> bytes:
    # The SDK's layout: C order of (cols, rows), flat index j*ROWS + i for pixel (i, j).
    return image.tobytes() if row_major else image.T.tobytes()


def magnitude_buffer(i: int, j: int, rng: np.random.Generator, row_major: bool = False) -> bytes:
    """uint32 magnitudes with one bright pixel (i, j)."""
    image = rng.integers(0, 10, size=(ROWS, COLS)).astype("<u4")
    image[i, j] = 50_000
    return _flat(image, row_major)


def complex_buffer(i: int, j: int, rng: np.random.Generator, row_major: bool = False) -> bytes:
    image = (rng.normal(size=(ROWS, COLS)) + 1j * rng.normal(size=(ROWS, COLS))).astype("<c8")
    image[i, j] = 3000 + 4000j
    return _flat(image, row_major)


def build_release(root: pathlib.Path, generation: str = "2020", gzip_lidar: bool = False, row_major: bool = False,
                  tracklog_axes: np.ndarray | None = None) -> Truth:
    """Write ``root/2020-02-03_2252/001/`` with every stream kind; returns what was written.

    ``row_major`` lays SAR pixels out as flat index i*COLS + j instead of the SDK's j*ROWS + i.
    ``tracklog_axes``: the tracklog's attitudes rotate these axes (given in forward-right-down, as
    columns) into ECEF instead of the IMU's own, e.g. ``diag(1, -1, -1)`` for x forward, y left, z up.
    """
    rng = np.random.default_rng(7)
    scene = root / "2020-02-03_2252" / "001"
    truth = Truth()
    times = np.arange(0, 2.0, 0.1)
    for serial, side in SERIALS.items():
        images, states = [], []
        truth.sar[side] = []
        for k, t in enumerate(times):
            frame = sar_frame(side, float(t) + (0.003 if side == "right" else 0.0), k)
            truth.sar[side].append(frame)
            p_enu, R_ecef_imu, _ = vehicle(float(t))
            pos = enu_to_ecef(p_enu)
            i, j = frame.bright_ij
            if generation == "2020":
                data = magnitude_buffer(i, j, rng, row_major)
                images.append(enc.image_2020(frame.timestamp_s, wxyz(R_ecef_imu), pos, k, frame.origin_ecef, frame.di_ecef, frame.dj_ecef, ROWS, COLS, data))
            else:
                data = complex_buffer(i, j, rng, row_major)
                images.append(enc.image_2021(frame.timestamp_s, wxyz(R_ecef_imu), pos, k, frame.origin_ecef, frame.di_ecef, frame.dj_ecef, ROWS, COLS, data))
            points = [
                enc.point(frame.timestamp_s, frame.target_ecef, 55.0, 10.5, -1.25, 0.1, 0.01, 17.0, 4.0 if generation == "2021" else None),
                enc.point(frame.timestamp_s, frame.target_ecef + 1.0, 20.0, 12.0, 0.5, -0.2, 0.0, 9.0, 2.0 if generation == "2021" else None),
            ]
            if k == 3:
                points.append(enc.point(frame.timestamp_s, (float("nan"),) * 3, 1.0, float("nan"), 0.0, float("nan"), 0.0, 1.0, 1.0 if generation == "2021" else None))
            if generation == "2020":
                states.append(enc.tracker_state_2020(frame.timestamp_s, points, k))
            else:
                states.append(enc.tracker_state_2021(frame.timestamp_s, points, k, wxyz(R_ecef_imu), pos))
        truth.n_detections[side] = sum(3 if k == 3 else 2 for k in range(len(times)))
        enc.write_stream(scene / f"{serial}_images.pbs", images, header=True)
        enc.write_stream(scene / f"{serial}_points.pbs", states, header=True)
    poses = []
    for k, t in enumerate(np.arange(-0.2, 2.2, 0.02)):
        p_enu, R_ecef_imu, _ = vehicle(float(t))
        attitude = R_ecef_imu if tracklog_axes is None else R_ecef_imu @ tracklog_axes
        poses.append(enc.position_record(T0_S + float(t), wxyz(attitude), enu_to_ecef(p_enu), k))
        truth.tracklog_s.append(T0_S + float(t))
    enc.write_stream(scene / "vn200.pbs", poses, header=True)
    sweeps = []
    for k, t in enumerate(times):
        frame = truth.sar["left"][k]
        pts = [enc.lidar_point(frame.timestamp_s, frame.target_ecef, (3.0, 10.0, 0.5), 200)]
        pts += [enc.lidar_point(frame.timestamp_s + 1e-4 * n, frame.target_ecef + n, (3.0 + n, 10.0, 0.5), n * 40) for n in range(1, 5)]
        if k == 2:
            pts.append(enc.lidar_point(frame.timestamp_s, (float("nan"),) * 3, (float("nan"),) * 3, 1))
        sweeps.append(enc.lidar_frame(T0_S + float(t) + 0.001, pts))
    enc.write_stream(scene / "lidar" / "00" / "stream.pbs", sweeps, header=False, gzip=gzip_lidar)
    R, D, A = 16, 8, 4
    enc.write_stream(
        scene / "range_Doppler" / "left_model.pbs",
        [enc.rd_model(A, (0.0, 0.176, R), (-D / 2 * 0.1, 0.1, D), [(0.0019 * a, 0.0, 0.0) for a in range(A)], 0.0039)],
    )
    cubes = []
    for k in range(5):
        cube = np.zeros((R, D, A), np.complex64)
        cube[3 + k, 5, :] = 1 + 2j
        cubes.append(enc.rd_frame(T0_S + 0.05 * k, cube))
    enc.write_stream(scene / "range_Doppler" / "left_rd.pbs", cubes)
    enc.write_stream(scene / "camera" / "index.pbs", [enc.camera_index(T0_S + k / 24, k) for k in range(30)])
    return truth
