"""Batched 3-D rotations written as elementwise products and sums in a fixed order.

``numpy.matmul`` and ``numpy.einsum`` hand small products to BLAS or to SIMD
kernels whose summation order and fused multiply-adds depend on the BLAS build,
its thread count and the CPU; the simulator's outputs must not.  Elementwise
numpy arithmetic rounds every element the same way everywhere (no fusing, no
reordering), so ``R v`` is spelled out as ``(R[:, 0] v0 + R[:, 1] v1) + R[:, 2] v2``.
On the simulator's ``[S, M, 3]`` arrays it is as fast as the ``einsum`` it replaces.
"""

from __future__ import annotations

import numpy as np


def rotate(rotation: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """``rotation @ vectors``: rotations ``[..., 3, 3]`` applied to vectors ``[..., 3]`` (broadcast), ``[..., 3]``."""
    return (
        vectors[..., 0, None] * rotation[..., :, 0]
        + vectors[..., 1, None] * rotation[..., :, 1]
        + vectors[..., 2, None] * rotation[..., :, 2]
    )


def unrotate(rotation: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """``rotation.T @ vectors`` (the inverse rotation), shapes as in :func:`rotate`."""
    return (
        vectors[..., 0, None] * rotation[..., 0, :]
        + vectors[..., 1, None] * rotation[..., 1, :]
        + vectors[..., 2, None] * rotation[..., 2, :]
    )


def compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a @ b`` for rotations ``[..., 3, 3]`` (broadcast), ``[..., 3, 3]``."""
    return np.stack([rotate(a, b[..., :, j]) for j in range(3)], axis=-1)


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``sum(a * b, axis=-1)`` of vectors ``[..., 3]`` (broadcast), ``[...]``."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]
