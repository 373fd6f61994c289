"""Interpolation of the tracklog (IMU pose in ECEF) at arbitrary GPS times."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation, Slerp

from zendar_dataset.errors import ZendarError
from zendar_dataset.geometry.se3 import SE3


class PoseInterpolator:
    """Pose of the IMU in ECEF at any time inside the tracklog's span.

    Translation is interpolated linearly and rotation by Slerp between the two
    bracketing samples. Times outside ``[timestamp_ns[0], timestamp_ns[-1]]``
    raise: a pose guessed by extrapolation would silently misplace labels.

    Parameters
    ----------
    timestamp_ns
        ``[K]`` int64 GPS nanoseconds, strictly increasing, ``K >= 2``.
    position_ecef
        ``[K, 3]`` float64, IMU origin in ECEF metres.
    attitude_wxyz
        ``[K, 4]`` float64 quaternions (w, x, y, z) rotating IMU-frame vectors to ECEF.
    """

    def __init__(
        self, timestamp_ns: ArrayLike, position_ecef: ArrayLike, attitude_wxyz: ArrayLike
    ) -> None:
        t = np.asarray(timestamp_ns)
        p = np.asarray(position_ecef, dtype=np.float64)
        q = np.asarray(attitude_wxyz, dtype=np.float64)
        problems = []
        if t.ndim != 1 or not np.issubdtype(t.dtype, np.integer):
            problems.append(f"tracklog timestamp_ns must be a 1-D integer array, got {t.dtype}{list(t.shape)}")
        elif t.shape[0] < 2:
            problems.append(f"tracklog needs at least 2 samples to interpolate, got {t.shape[0]}")
        elif np.any(np.diff(t) <= 0):
            first = int(np.flatnonzero(np.diff(t) <= 0)[0])
            problems.append(
                f"tracklog timestamp_ns must be strictly increasing; sample {first + 1} "
                f"({int(t[first + 1])}) does not follow sample {first} ({int(t[first])})"
            )
        n = t.shape[0] if t.ndim == 1 else -1
        if p.shape != (n, 3):
            problems.append(f"tracklog position_ecef must be [{n}, 3], got {list(p.shape)}")
        if q.shape != (n, 4):
            problems.append(f"tracklog attitude_wxyz must be [{n}, 4], got {list(q.shape)}")
        elif np.any(np.linalg.norm(q, axis=1) < 1e-12) or not np.all(np.isfinite(q)):
            problems.append("tracklog attitude_wxyz holds zero or non-finite quaternions")
        if problems:
            raise ZendarError("; ".join(problems))
        self.timestamp_ns = t.astype(np.int64)
        self.position_ecef = p
        self.attitude_wxyz = q
        # Times relative to the first sample are exact in float64 for spans < 104 days.
        self._slerp = Slerp(
            (self.timestamp_ns - self.timestamp_ns[0]).astype(np.float64),
            Rotation.from_quat(q, scalar_first=True),
        )

    @property
    def span_ns(self) -> tuple[int, int]:
        return int(self.timestamp_ns[0]), int(self.timestamp_ns[-1])

    def _check_inside(self, t: np.ndarray) -> None:
        start, end = self.span_ns
        outside = (t < start) | (t > end)
        if np.any(outside):
            bad = int(t[outside][0])
            raise ZendarError(
                f"pose requested at timestamp_ns={bad}, outside the tracklog span "
                f"[{start}, {end}] ({outside.sum()} of {t.size} times outside); "
                "poses are not extrapolated"
            )

    def at(self, timestamp_ns: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Interpolate the pose at the given times.

        Parameters
        ----------
        timestamp_ns
            Scalar or ``[N]`` int64 GPS nanoseconds inside the tracklog span.

        Returns
        -------
        position_ecef : np.ndarray
            ``[N, 3]`` float64 metres.
        attitude_wxyz : np.ndarray
            ``[N, 4]`` float64 unit quaternions (IMU -> ECEF), ``w >= 0``.
        """
        t = np.atleast_1d(np.asarray(timestamp_ns)).astype(np.int64).reshape(-1)
        self._check_inside(t)
        # Index of the segment start; the last sample belongs to the final segment.
        idx = np.clip(np.searchsorted(self.timestamp_ns, t, side="right") - 1, 0, len(self.timestamp_ns) - 2)
        t0 = self.timestamp_ns[idx]
        fraction = ((t - t0) / (self.timestamp_ns[idx + 1] - t0))[:, None]
        p0 = self.position_ecef[idx]
        position = p0 + fraction * (self.position_ecef[idx + 1] - p0)
        rotation = self._slerp((t - self.timestamp_ns[0]).astype(np.float64))
        return position, rotation.as_quat(canonical=True, scalar_first=True)

    def ecef_T_imu(self, timestamp_ns: int) -> SE3:
        """The IMU pose at one time as a rigid transform (IMU points -> ECEF)."""
        position, attitude = self.at(np.int64(timestamp_ns))
        return SE3.from_wxyz(attitude[0], position[0])
