"""Rigid transforms in 3-D."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from zendar_dataset.geometry.quaternion import matrix_to_quat_wxyz, quat_wxyz_to_matrix


@dataclass(frozen=True)
class SE3:
    """A rigid transform ``a_T_b``: ``p_a = rotation @ p_b + translation``.

    Attributes
    ----------
    rotation
        ``[3, 3]`` float64 rotation matrix (frame b axes expressed in frame a).
    translation
        ``[3]`` float64, the origin of frame b in frame a (metres).
    """

    rotation: np.ndarray
    translation: np.ndarray

    def __post_init__(self) -> None:
        rotation = np.array(self.rotation, dtype=np.float64)
        translation = np.array(self.translation, dtype=np.float64).reshape(-1)
        if rotation.shape != (3, 3):
            raise ValueError(f"SE3 rotation must be [3, 3], got {rotation.shape}")
        if translation.shape != (3,):
            raise ValueError(f"SE3 translation must be [3], got {translation.shape}")
        rotation.setflags(write=False)
        translation.setflags(write=False)
        object.__setattr__(self, "rotation", rotation)
        object.__setattr__(self, "translation", translation)

    @classmethod
    def identity(cls) -> SE3:
        return cls(np.eye(3), np.zeros(3))

    @classmethod
    def from_wxyz(cls, q_wxyz: ArrayLike, translation: ArrayLike) -> SE3:
        """Build from a quaternion ``[4]`` (w, x, y, z) and a translation ``[3]`` in metres."""
        return cls(quat_wxyz_to_matrix(q_wxyz), translation)

    @classmethod
    def from_matrix(cls, matrix: ArrayLike) -> SE3:
        """Build from a homogeneous ``[4, 4]`` matrix."""
        m = np.asarray(matrix, dtype=np.float64)
        if m.shape != (4, 4):
            raise ValueError(f"homogeneous matrix must be [4, 4], got {m.shape}")
        return cls(m[:3, :3], m[:3, 3])

    def compose(self, other: SE3) -> SE3:
        """Chain transforms: ``a_T_b.compose(b_T_c)`` is ``a_T_c``."""
        return SE3(
            self.rotation @ other.rotation,
            self.rotation @ other.translation + self.translation,
        )

    def inverse(self) -> SE3:
        """``a_T_b.inverse()`` is ``b_T_a``."""
        rotation_t = self.rotation.T
        return SE3(rotation_t, -rotation_t @ self.translation)

    def transform_points(self, points: ArrayLike) -> np.ndarray:
        """Map points ``[..., 3]`` from frame b to frame a (float64 result)."""
        p = np.asarray(points, dtype=np.float64)
        if p.shape[-1:] != (3,):
            raise ValueError(f"points must have shape [..., 3], got {p.shape}")
        return p @ self.rotation.T + self.translation

    def rotate_vectors(self, vectors: ArrayLike) -> np.ndarray:
        """Rotate free vectors ``[..., 3]`` (velocities, directions) without translating."""
        v = np.asarray(vectors, dtype=np.float64)
        if v.shape[-1:] != (3,):
            raise ValueError(f"vectors must have shape [..., 3], got {v.shape}")
        return v @ self.rotation.T

    def as_matrix(self) -> np.ndarray:
        """The homogeneous ``[4, 4]`` float64 matrix."""
        m = np.eye(4)
        m[:3, :3] = self.rotation
        m[:3, 3] = self.translation
        return m

    def as_wxyz(self) -> np.ndarray:
        """The rotation as a unit quaternion ``[4]`` (w, x, y, z), ``w >= 0``."""
        return matrix_to_quat_wxyz(self.rotation)
