"""Moving points between sensor, ego, ENU, ECEF and SAR-pixel coordinates.

Frames (docs/architecture.md): ego is x forward, y left, z up; the IMU is
forward, right, down. The calibration entry ``"imu"`` is ``ego_T_imu``, the
tracklog gives ``ecef_T_imu(t)``, so ``ecef_T_ego(t) = ecef_T_imu(t) ∘ imu_T_ego``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from zendar_dataset.errors import ZendarError
from zendar_dataset.geometry.geodesy import LocalENU
from zendar_dataset.geometry.poses import PoseInterpolator
from zendar_dataset.geometry.se3 import SE3

IMU_SENSOR = "imu"


def ego_T_sensor(entry: Any) -> SE3:
    """The pose of a sensor in the ego frame from its calibration entry.

    Parameters
    ----------
    entry
        A mapping with ``"rotation_wxyz"`` [4] and ``"translation_m"`` [3] (format v1
        calibration), or an object with those attributes.
    """
    if isinstance(entry, Mapping):
        rotation_wxyz = entry.get("rotation_wxyz")
        translation_m = entry.get("translation_m")
    else:
        rotation_wxyz = getattr(entry, "rotation_wxyz", None)
        translation_m = getattr(entry, "translation_m", None)
    if rotation_wxyz is None or translation_m is None:
        raise ZendarError(
            "calibration entry needs 'rotation_wxyz' [4] and 'translation_m' [3]; "
            f"got {entry!r}"
        )
    return SE3.from_wxyz(rotation_wxyz, translation_m)


class EgoPoses:
    """The ego pose at any time of a scene, in ECEF and in the scene's local ENU frame.

    Parameters
    ----------
    tracklog
        The IMU trajectory (:class:`PoseInterpolator`).
    ego_T_imu
        The IMU's calibration (``"imu"`` entry), IMU points -> ego points.
    enu
        The scene's local ENU frame (its ``enu_origin``).
    """

    def __init__(self, tracklog: PoseInterpolator, ego_T_imu: SE3, enu: LocalENU) -> None:
        self.tracklog = tracklog
        self.imu_T_ego = ego_T_imu.inverse()
        self.enu = enu

    def ecef_T_ego(self, timestamp_ns: int) -> SE3:
        """Ego -> ECEF at one GPS time (interpolated; raises outside the tracklog)."""
        return self.tracklog.ecef_T_imu(timestamp_ns).compose(self.imu_T_ego)

    def enu_T_ego(self, timestamp_ns: int) -> SE3:
        """Ego -> local ENU at one GPS time."""
        return self.enu.enu_T_ecef.compose(self.ecef_T_ego(timestamp_ns))

    def sensor_to_ecef(self, points_sensor: ArrayLike, ego_T_sensor: SE3, timestamp_ns: int) -> np.ndarray:
        """Sensor-frame points ``[..., 3]`` observed at ``timestamp_ns`` to ECEF ``[..., 3]``."""
        return self.ecef_T_ego(timestamp_ns).compose(ego_T_sensor).transform_points(points_sensor)

    def ecef_to_sensor(self, points_ecef: ArrayLike, ego_T_sensor: SE3, timestamp_ns: int) -> np.ndarray:
        """ECEF points ``[..., 3]`` to the sensor frame at ``timestamp_ns``."""
        sensor_T_ecef = self.ecef_T_ego(timestamp_ns).compose(ego_T_sensor).inverse()
        return sensor_T_ecef.transform_points(points_ecef)

    def ego_to_enu(self, points_ego: ArrayLike, timestamp_ns: int) -> np.ndarray:
        return self.enu_T_ego(timestamp_ns).transform_points(points_ego)

    def enu_to_ego(self, points_enu: ArrayLike, timestamp_ns: int) -> np.ndarray:
        return self.enu_T_ego(timestamp_ns).inverse().transform_points(points_enu)

    def ego_to_ecef(self, points_ego: ArrayLike, timestamp_ns: int) -> np.ndarray:
        return self.ecef_T_ego(timestamp_ns).transform_points(points_ego)

    def ecef_to_ego(self, points_ecef: ArrayLike, timestamp_ns: int) -> np.ndarray:
        return self.ecef_T_ego(timestamp_ns).inverse().transform_points(points_ecef)


def sar_pixel_to_ecef(
    i: ArrayLike, j: ArrayLike, origin_ecef: ArrayLike, di_ecef: ArrayLike, dj_ecef: ArrayLike
) -> np.ndarray:
    """ECEF position of SAR pixel ``(i, j)`` (fractional allowed): ``origin + i·di + j·dj``.

    Parameters
    ----------
    i, j
        Row and column indices, broadcastable to each other, shape ``[...]``.
    origin_ecef, di_ecef, dj_ecef
        ``[3]`` float64 ECEF metres: pixel (0, 0) and the steps along rows and columns.

    Returns
    -------
    np.ndarray
        ``[..., 3]`` float64 ECEF metres.
    """
    i_arr, j_arr = np.broadcast_arrays(np.asarray(i, np.float64), np.asarray(j, np.float64))
    origin, di, dj = (np.asarray(v, np.float64).reshape(3) for v in (origin_ecef, di_ecef, dj_ecef))
    return origin + i_arr[..., None] * di + j_arr[..., None] * dj


def ecef_to_sar_pixel(
    points_ecef: ArrayLike, origin_ecef: ArrayLike, di_ecef: ArrayLike, dj_ecef: ArrayLike
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fractional SAR pixel coordinates of ECEF points (least squares onto the image plane).

    Returns
    -------
    i, j : np.ndarray
        ``[...]`` float64 fractional row and column.
    distance_m : np.ndarray
        ``[...]`` float64 distance of each point from the image plane (metres), the
        least-squares residual, so callers can reject points far off the plane.
    """
    p = np.asarray(points_ecef, dtype=np.float64)
    if p.shape[-1:] != (3,):
        raise ValueError(f"points_ecef must have shape [..., 3], got {p.shape}")
    origin, di, dj = (np.asarray(v, np.float64).reshape(3) for v in (origin_ecef, di_ecef, dj_ecef))
    basis = np.stack([di, dj], axis=1)  # [3, 2]
    gram = basis.T @ basis
    if abs(np.linalg.det(gram)) < 1e-18 * max(1.0, float(np.trace(gram))) ** 2:
        raise ValueError("SAR pixel steps di_ecef and dj_ecef are parallel or zero")
    offset = p - origin
    ij = np.linalg.solve(gram, (offset @ basis).reshape(-1, 2).T).T.reshape(p.shape[:-1] + (2,))
    residual = offset - ij @ basis.T
    return ij[..., 0], ij[..., 1], np.linalg.norm(residual, axis=-1)
