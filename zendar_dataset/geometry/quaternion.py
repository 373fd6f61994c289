"""Unit quaternions in scalar-first (w, x, y, z) order, as stored by format v1.

Built on :class:`scipy.spatial.transform.Rotation` (``scalar_first=True``), so
normalisation and the double cover are handled by a maintained library.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation


def quat_wxyz_to_matrix(q_wxyz: ArrayLike) -> np.ndarray:
    """Convert quaternions to rotation matrices.

    Parameters
    ----------
    q_wxyz
        ``[..., 4]`` quaternions, scalar first. They are normalised first, so a
        quaternion written with limited precision is still accepted.

    Returns
    -------
    np.ndarray
        ``[..., 3, 3]`` float64 rotation matrices.
    """
    q = np.asarray(q_wxyz, dtype=np.float64)
    if q.shape[-1:] != (4,):
        raise ValueError(f"quaternions must have shape [..., 4], got {q.shape}")
    flat = q.reshape(-1, 4)
    norms = np.linalg.norm(flat, axis=1)
    if np.any(~np.isfinite(norms)) or np.any(norms < 1e-12):
        raise ValueError("quaternions must be finite and non-zero")
    matrices = Rotation.from_quat(flat, scalar_first=True).as_matrix()
    return matrices.reshape(q.shape[:-1] + (3, 3))


def matrix_to_quat_wxyz(rotation: ArrayLike) -> np.ndarray:
    """Convert rotation matrices to unit quaternions with a non-negative scalar part.

    Parameters
    ----------
    rotation
        ``[..., 3, 3]`` rotation matrices.

    Returns
    -------
    np.ndarray
        ``[..., 4]`` float64 quaternions (w, x, y, z), ``w >= 0``.
    """
    matrices = np.asarray(rotation, dtype=np.float64)
    if matrices.shape[-2:] != (3, 3):
        raise ValueError(f"rotation matrices must have shape [..., 3, 3], got {matrices.shape}")
    flat = matrices.reshape(-1, 3, 3)
    q = Rotation.from_matrix(flat).as_quat(canonical=True, scalar_first=True)
    return q.reshape(matrices.shape[:-2] + (4,))
