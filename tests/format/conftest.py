"""Small format-v1 datasets written with the writer, for the format tests."""

from __future__ import annotations

import hashlib
import os
import pathlib

import numpy as np
import pytest

from tests.datasets import calibration_json
from zendar_dataset.format import DatasetWriter

R, D, A = 16, 8, 4
SAR_H, SAR_W = 12, 10
CAM_H, CAM_W = 6, 8
FRAME_NS = 100_000_000
T0_NS = 1_300_000_000_000_000_000
ENU_ORIGIN = {"lat_deg": 37.7749, "lon_deg": -122.4194, "height_m": 12.5}


def make_calibration() -> dict:
    """A calibration with two radars, a camera, a lidar and the IMU."""
    return calibration_json(n_rx=A, camera_width=CAM_W, camera_height=CAM_H, imu_translation_m=[-2.0, 0.0, 0.3])


def write_scene(writer, rng: np.random.Generator, *, n_frames: int = 4, labels: bool = True) -> None:
    """Fill a SceneWriter with every stream: radar left/right, SAR left/right, camera, lidar, tracklog, labels."""
    for k in range(n_frames):
        t = T0_NS + k * FRAME_NS
        for sensor in ("left", "right"):
            cube = (rng.standard_normal((R, D, A)) + 1j * rng.standard_normal((R, D, A))).astype(np.complex64)
            writer.append_radar(sensor, t, cube)
        if k % 2 == 1:
            for sensor in ("left", "right"):
                image = (rng.standard_normal((SAR_H, SAR_W)) + 1j * rng.standard_normal((SAR_H, SAR_W))).astype(np.complex64)
                origin = np.array([-2_700_000.0, -4_290_000.0, 3_850_000.0]) + k
                writer.append_sar(sensor, t, image, origin, [0.04, 0.0, 0.0], [0.0, 0.04, 0.0], [t - 50_000_000, t + 50_000_000])
        writer.append_camera("front", t + 1_000_000, rng.integers(0, 256, (CAM_H, CAM_W, 3), dtype=np.uint8))
        writer.append_lidar("top", t + 2_000_000, rng.standard_normal((int(rng.integers(0, 30)), 4)).astype(np.float32))
    k = np.arange(n_frames * 10)
    position = np.array([-2_700_000.0, -4_290_000.0, 3_850_000.0]) + np.outer(k, [0.1, 0.2, 0.0])
    attitude = np.tile([1.0, 0.0, 0.0, 0.0], (k.size, 1))
    writer.write_tracklog(T0_NS - FRAME_NS + k * 10_000_000, position, attitude)
    if labels:
        sar_t = T0_NS + FRAME_NS * np.arange(1, n_frames, 2)
        # Two cars in the first SAR frame, none in the others.
        n = 2
        writer.write_labels(
            {
                "timestamp_ns": np.full(n, sar_t[0], dtype=np.int64),
                "x": rng.uniform(-20, 20, n),
                "y": rng.uniform(-20, 20, n),
                "length": np.full(n, 4.5),
                "width": np.full(n, 1.8),
                "yaw": rng.uniform(-np.pi, np.pi, n),
                "vx": rng.uniform(-10, 10, n),
                "vy": rng.uniform(-10, 10, n),
                "track_id": np.arange(n, dtype=np.int64) + 7,
            }
        )


def make_dataset(root: pathlib.Path, backend: str = "zarr", *, seed: int = 0, n_frames: int = 4) -> pathlib.Path:
    """A dataset with scenes s0, s1 (train, labelled), s2 (val, labelled) and s3 (test, labels withheld)."""
    rng = np.random.default_rng(seed)
    writer = DatasetWriter(root, "tiny", backend=backend)
    for scene_id in ("s0", "s1", "s2", "s3"):
        with writer.scene(scene_id, enu_origin=ENU_ORIGIN, calibration=make_calibration()) as scene:
            write_scene(scene, rng, n_frames=n_frames, labels=scene_id != "s3")
    writer.finalize({"train": ["s0", "s1"], "val": ["s2"], "test": ["s3"]})
    return root


def make_small_dataset(root: pathlib.Path, backend: str = "zarr", *, seed: int = 0) -> pathlib.Path:
    """One labelled scene ``s0`` (train; val and test empty), every stream, for the fault and rule tests."""
    rng = np.random.default_rng(seed)
    writer = DatasetWriter(root, "small", backend=backend)
    with writer.scene("s0", enu_origin=ENU_ORIGIN, calibration=make_calibration()) as scene:
        write_scene(scene, rng, n_frames=4)
    writer.finalize({"train": ["s0"]})
    return root


def tree_digest(root: pathlib.Path) -> dict[str, tuple[str, int]]:
    """Hash and mtime of every file under ``root``: detects any write."""
    out = {}
    for path in sorted(pathlib.Path(root).rglob("*")):
        if path.is_file():
            out[str(path.relative_to(root))] = (hashlib.sha256(path.read_bytes()).hexdigest(), os.stat(path).st_mtime_ns)
    return out


@pytest.fixture(params=["zarr", "hdf5"])
def backend(request) -> str:
    return request.param


@pytest.fixture
def dataset_root(tmp_path, backend) -> pathlib.Path:
    return make_dataset(tmp_path / f"ds-{backend}", backend)
