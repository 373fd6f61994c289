"""A pinhole camera with radial-tangential distortion rendering shaded boxes.

Each pixel's ray is found by undistorting its coordinates (the inverse of the
OpenCV model stored in the calibration, ``k1, k2, p1, p2, k3``) and cast into
the world: boxes are flat-shaded by a fixed sun, the ground is asphalt grey,
anything else is sky.  The camera frame is the optical frame (x right, y down,
z forward).
"""

from __future__ import annotations

import numpy as np

from zendar_dataset.sim.raycast import GROUND, NOTHING, cast_rays
from zendar_dataset.sim.rotate import dot, rotate
from zendar_dataset.sim.world import BoxSet

SUN_DIRECTION_ENU = np.array([0.4, -0.3, 0.87]) / np.linalg.norm([0.4, -0.3, 0.87])
SKY_RGB = np.array([150.0, 190.0, 235.0])
GROUND_RGB = np.array([85.0, 85.0, 90.0])
MAX_RANGE_M = 200.0


def distort(normalized: np.ndarray, distortion: np.ndarray) -> np.ndarray:
    """Apply the OpenCV radial-tangential model to normalised coordinates ``[..., 2]``."""
    k1, k2, p1, p2, k3 = distortion
    x, y = normalized[..., 0], normalized[..., 1]
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2**2 + k3 * r2**3
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return np.stack([xd, yd], axis=-1)


def project(points_camera: np.ndarray, k: np.ndarray, distortion: np.ndarray) -> np.ndarray:
    """Pixel coordinates ``[..., 2]`` (column u, row v) of camera-frame points ``[..., 3]`` (z > 0)."""
    p = np.asarray(points_camera, dtype=np.float64)
    distorted = distort(p[..., :2] / p[..., 2:3], distortion)
    return distorted * [k[0, 0], k[1, 1]] + [k[0, 2], k[1, 2]]


def pixel_rays(k: np.ndarray, distortion: np.ndarray, height: int, width: int) -> np.ndarray:
    """``[H, W, 3]`` unit ray directions (camera frame) through every pixel centre."""
    v, u = np.mgrid[0:height, 0:width].astype(np.float64)
    distorted = np.stack([(u - k[0, 2]) / k[0, 0], (v - k[1, 2]) / k[1, 1]], axis=-1)
    undistorted = distorted.copy()
    for _ in range(20):  # fixed-point inversion, converges for mild distortion
        undistorted += distorted - distort(undistorted, distortion)
    rays = np.concatenate([undistorted, np.ones((height, width, 1))], axis=-1)
    return rays / np.linalg.norm(rays, axis=-1, keepdims=True)


def render(
    rays_camera: np.ndarray, enu_r_camera: np.ndarray, position_enu: np.ndarray, boxes: BoxSet
) -> np.ndarray:
    """Render one frame ``[H, W, 3]`` uint8 RGB from the true camera pose."""
    height, width, _ = rays_camera.shape
    directions = rotate(enu_r_camera, rays_camera.reshape(-1, 3))
    distance, hit, normal = cast_rays(position_enu, directions, boxes, MAX_RANGE_M)
    shade = 0.45 + 0.55 * np.clip(dot(normal, SUN_DIRECTION_ENU), 0.0, 1.0)
    rgb = np.empty((directions.shape[0], 3))
    on_box = hit >= 0
    rgb[on_box] = boxes.color[hit[on_box]] * shade[on_box, None]
    on_ground = hit == GROUND
    # Haze towards the horizon keeps far ground from aliasing.
    haze = np.clip(distance[on_ground] / MAX_RANGE_M, 0.0, 1.0)[:, None]
    rgb[on_ground] = GROUND_RGB * (1 - haze) + SKY_RGB * haze
    rgb[hit == NOTHING] = SKY_RGB
    return np.clip(np.rint(rgb), 0, 255).astype(np.uint8).reshape(height, width, 3)
