"""Pure geometry: quaternions (wxyz), rigid transforms, pyproj conversions, pose interpolation.

Nothing here does I/O. Transforms are named for where they take points:
``ecef_T_imu`` maps points in the IMU frame to ECEF (``p_ecef = R p_imu + t``).
"""

from zendar_dataset.geometry.geodesy import LocalENU, ecef_to_geodetic, geodetic_to_ecef, local_up_ecef
from zendar_dataset.geometry.poses import PoseInterpolator
from zendar_dataset.geometry.quaternion import matrix_to_quat_wxyz, quat_wxyz_to_matrix
from zendar_dataset.geometry.se3 import SE3

__all__ = [
    "SE3",
    "LocalENU",
    "PoseInterpolator",
    "ecef_to_geodetic",
    "geodetic_to_ecef",
    "local_up_ecef",
    "matrix_to_quat_wxyz",
    "quat_wxyz_to_matrix",
]
