"""Which solid bodies of the simulated street overlap: oriented boxes standing on the ground.

The world builder places parked cars, poles, trees and buildings, and the
traffic generator draws moving cars, by rejection: a candidate that would
overlap a body already placed (or the ego) is drawn again.  The test is the
separating-axis theorem for oriented rectangles in the ground plane, plus the
boxes' height intervals (a tree canopy may overhang a parked car).  It is
vectorised over many boxes with numpy; a geometry library such as shapely would
build one polygon object per box and is not a dependency of the package.
"""

from __future__ import annotations

import numpy as np

# Bodies must keep this gap (metres) in the ground plane: two cars never touch, and the test of a
# moving car at sampled times must not miss a contact between samples (see traffic.CHECK_STEP_S).
DEFAULT_MARGIN_M = 0.3


def _corners(center_xy: np.ndarray, half_lw: np.ndarray, yaw_rad: np.ndarray) -> np.ndarray:
    """``[..., 4, 2]`` ground-plane corners of boxes ``[..., 2]``, ``[..., 2]``, ``[...]``."""
    signs = np.array([[1.0, 1.0], [1.0, -1.0], [-1.0, -1.0], [-1.0, 1.0]])
    local = signs * half_lw[..., None, :]  # [..., 4, 2]
    c, s = np.cos(yaw_rad)[..., None], np.sin(yaw_rad)[..., None]
    x = c * local[..., 0] - s * local[..., 1]
    y = s * local[..., 0] + c * local[..., 1]
    return np.stack([x, y], axis=-1) + center_xy[..., None, :]


def boxes_overlap(
    center_a: np.ndarray,
    size_a: np.ndarray,
    yaw_a: np.ndarray,
    center_b: np.ndarray,
    size_b: np.ndarray,
    yaw_b: np.ndarray,
    margin_m: float = 0.0,
) -> np.ndarray:
    """Whether box pairs overlap (broadcast over leading axes).

    Parameters
    ----------
    center_a, center_b : numpy.ndarray
        ``[..., 3]`` box centres (x, y in the ground plane, z the centre height), metres.
    size_a, size_b : numpy.ndarray
        ``[..., 3]`` length (along the yaw), width, height, metres.
    yaw_a, yaw_b : numpy.ndarray
        ``[...]`` headings of the length axes, radians.
    margin_m : float
        Each box is grown by this much on every side in the ground plane before the test.

    Returns
    -------
    numpy.ndarray
        ``[...]`` bool: the footprints (grown by ``margin_m``) intersect and the height intervals overlap.
    """
    center_a, center_b = np.asarray(center_a, np.float64), np.asarray(center_b, np.float64)
    size_a, size_b = np.asarray(size_a, np.float64), np.asarray(size_b, np.float64)
    half_a = size_a[..., :2] / 2 + margin_m
    half_b = size_b[..., :2] / 2 + margin_m
    corners_a = _corners(center_a[..., :2], half_a, np.asarray(yaw_a, np.float64))
    corners_b = _corners(center_b[..., :2], half_b, np.asarray(yaw_b, np.float64))
    corners_a, corners_b = np.broadcast_arrays(corners_a, corners_b)
    separated = np.zeros(corners_a.shape[:-2], bool)
    # The candidate separating axes are the two edge normals of each rectangle.
    for yaw in (np.asarray(yaw_a, np.float64), np.asarray(yaw_b, np.float64)):
        for angle in (yaw, yaw + np.pi / 2):
            axis = np.stack([np.cos(angle), np.sin(angle)], axis=-1)[..., None, :]
            proj_a = np.sum(corners_a * axis, axis=-1)
            proj_b = np.sum(corners_b * axis, axis=-1)
            separated |= (proj_a.max(-1) < proj_b.min(-1)) | (proj_b.max(-1) < proj_a.min(-1))
    bottom_a, top_a = center_a[..., 2] - size_a[..., 2] / 2, center_a[..., 2] + size_a[..., 2] / 2
    bottom_b, top_b = center_b[..., 2] - size_b[..., 2] / 2, center_b[..., 2] + size_b[..., 2] / 2
    separated |= (top_a <= bottom_b) | (top_b <= bottom_a)
    return ~separated
