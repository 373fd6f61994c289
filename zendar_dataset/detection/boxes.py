"""Labelled car boxes of one frame, moved to another time and tested against points.

The one points-in-boxes test of the package (:meth:`LabelBoxes.contains`): the fidelity report, the
automatic labels' quality, the label masks and the chain fit all use it.

Labels (docs/format.md, ``labels/moving_cars``) are boxes in the ego frame at a SAR frame's
timestamp; radar cubes come at other times. A box is moved to a cube's time with the ego poses (the
ego frame moves) and the car's own velocity over the time difference (the car moves).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from zendar_dataset.errors import ZendarError
from zendar_dataset.geometry.frames import EgoPoses

FIELDS = ("x", "y", "length", "width", "yaw", "vx", "vy")
# A radar point counts as on a car when it falls inside the car's box grown by this much: the
# range bin (0.18-0.6 m) plus the DOA error of a 4-antenna array at mid range (~1 deg -> 0.5 m at 30 m).
ON_CAR_MARGIN_M = 1.0


@dataclass(frozen=True)
class LabelBoxes:
    """Car boxes in the ego frame at ``timestamp_ns``; every array ``[B]`` float64.

    Attributes
    ----------
    timestamp_ns : int
        The time whose ego frame the boxes are in.
    x, y : numpy.ndarray
        Box centre, metres.
    length, width : numpy.ndarray
        Metres; length along the heading.
    yaw : numpy.ndarray
        Heading, radians from the ego x axis towards y.
    vx, vy : numpy.ndarray
        Velocity over ground, m/s, in the ego frame's axes.
    """

    timestamp_ns: int
    x: np.ndarray
    y: np.ndarray
    length: np.ndarray
    width: np.ndarray
    yaw: np.ndarray
    vx: np.ndarray
    vy: np.ndarray

    def __post_init__(self) -> None:
        shapes = {name: np.shape(getattr(self, name)) for name in FIELDS}
        if len(set(shapes.values())) != 1 or len(shapes["x"]) != 1:
            raise ZendarError(f"LabelBoxes fields must all be [B] arrays, got shapes {shapes}")

    def __len__(self) -> int:
        return int(np.shape(self.x)[0])

    @classmethod
    def of_frame(cls, labels: dict[str, np.ndarray], timestamp_ns: int) -> LabelBoxes:
        """The boxes of one label frame, from :meth:`SceneReader.labels` arrays."""
        rows = np.flatnonzero(labels["timestamp_ns"] == timestamp_ns)
        return cls(int(timestamp_ns), *(np.asarray(labels[name][rows], np.float64) for name in FIELDS))

    def moved_to(self, timestamp_ns: int, poses: EgoPoses) -> LabelBoxes:
        """The same cars at ``timestamp_ns``, in the ego frame of that time.

        Each centre moves by its velocity over the time difference (constant velocity; 0.1 s at
        15 m/s is 1.5 m, so the motion matters); headings and velocities turn with the ego frame.
        """
        dt_s = (int(timestamp_ns) - self.timestamp_ns) * 1e-9
        n = len(self)
        centre_then = np.stack([self.x, self.y, np.zeros(n)], axis=1)
        velocity_then = np.stack([self.vx, self.vy, np.zeros(n)], axis=1)
        heading_then = np.stack([np.cos(self.yaw), np.sin(self.yaw), np.zeros(n)], axis=1)
        ecef_T_then = poses.ecef_T_ego(self.timestamp_ns)
        now_T_ecef = poses.ecef_T_ego(int(timestamp_ns)).inverse()
        centre_ecef = ecef_T_then.transform_points(centre_then) + ecef_T_then.rotate_vectors(velocity_then) * dt_s
        centre_now = now_T_ecef.transform_points(centre_ecef)
        velocity_now = now_T_ecef.rotate_vectors(ecef_T_then.rotate_vectors(velocity_then))
        heading_now = now_T_ecef.rotate_vectors(ecef_T_then.rotate_vectors(heading_then))
        return LabelBoxes(
            int(timestamp_ns), centre_now[:, 0], centre_now[:, 1], self.length.copy(), self.width.copy(),
            np.arctan2(heading_now[:, 1], heading_now[:, 0]), velocity_now[:, 0], velocity_now[:, 1],
        )

    def contains(self, points_xy: np.ndarray, margin_m: float = 0.0) -> np.ndarray:
        """``[P, B]`` bool: point ``p`` lies inside box ``b`` grown by ``margin_m`` on every side.

        Parameters
        ----------
        points_xy : numpy.ndarray
            ``[P, 2]`` metres, in the boxes' ego frame.
        margin_m : float
            Added to each half-length and half-width.
        """
        points_xy = np.asarray(points_xy, np.float64).reshape(-1, 2)
        delta = points_xy[:, None, :] - np.stack([self.x, self.y], axis=1)[None]
        c, s = np.cos(self.yaw)[None], np.sin(self.yaw)[None]
        along = c * delta[..., 0] + s * delta[..., 1]
        across = -s * delta[..., 0] + c * delta[..., 1]
        return (np.abs(along) <= self.length[None] / 2 + margin_m) & (np.abs(across) <= self.width[None] / 2 + margin_m)


def nearest_label_frame(label_timestamps_ns: np.ndarray, timestamp_ns: int) -> int:
    """The label frame timestamp nearest ``timestamp_ns`` (earlier one on a tie).

    Parameters
    ----------
    label_timestamps_ns : numpy.ndarray
        ``[L]`` int64 distinct, sorted label frame timestamps (at least one).
    """
    stamps = np.asarray(label_timestamps_ns, np.int64)
    return int(stamps[int(np.argmin(np.abs(stamps - np.int64(timestamp_ns))))])
