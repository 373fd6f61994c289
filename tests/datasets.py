"""Building blocks shared by the test datasets of tests/format and tests/loader."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

_HALF = float(np.sqrt(0.5))
# IMU axes are forward, right, down: a half turn about the ego x axis.
IMU_ROTATION_WXYZ = [0.0, 1.0, 0.0, 0.0]


def calibration_json(*, n_rx: int, camera_width: int, camera_height: int, imu_translation_m: Sequence[float]) -> dict:
    """Format-v1 calibration JSON of the test rig.

    Radars ``left`` and ``right`` (boresight ±90° from ego x, ``n_rx`` receivers
    1.9 mm apart along y), camera ``front`` (OpenCV optical frame, principal
    point at the image centre), lidar ``top`` and the IMU at ``imu_translation_m``.
    """
    radar = {
        "center_frequency_hz": 77e9,
        "bandwidth_hz": 833e6,
        "range_bin_m": 0.18,
        "doppler_bin_mps": 0.1,
        "rx_positions_m": [[0.0, 0.0019 * a, 0.0] for a in range(n_rx)],
    }
    focal_px = 5.0
    return {
        "sensors": {
            "left": {"rotation_wxyz": [_HALF, 0.0, 0.0, _HALF], "translation_m": [-1.0, 0.9, 0.5], **radar},
            "right": {"rotation_wxyz": [_HALF, 0.0, 0.0, -_HALF], "translation_m": [-1.0, -0.9, 0.5], **radar},
            "front": {
                "rotation_wxyz": [0.5, -0.5, 0.5, -0.5],
                "translation_m": [-1.5, 0.0, 1.4],
                "K": [[focal_px, 0.0, camera_width / 2], [0.0, focal_px, camera_height / 2], [0.0, 0.0, 1.0]],
                "distortion": [0.0] * 5,
                "width": camera_width,
                "height": camera_height,
            },
            "top": {"rotation_wxyz": [1.0, 0.0, 0.0, 0.0], "translation_m": [-1.8, 0.0, 1.9]},
            "imu": {"rotation_wxyz": list(IMU_ROTATION_WXYZ), "translation_m": list(imu_translation_m)},
        }
    }
