"""A Velodyne VLP-16 model: 16 beams from -15 to +15 deg, one revolution per sweep.

Every firing of a sweep is cast at the sweep's timestamp (the ~0.1 s rolling
scan of the real sensor is not modelled).  Range noise is 2 cm; intensity is
the surface reflectivity times the cosine of the incidence angle, 0-255.
"""

from __future__ import annotations

import numpy as np

from zendar_dataset.sim.raycast import GROUND, NOTHING, cast_rays
from zendar_dataset.sim.rotate import dot, rotate
from zendar_dataset.sim.world import BoxSet

N_BEAMS = 16
MAX_RANGE_M = 100.0
RANGE_NOISE_M = 0.02
GROUND_REFLECTIVITY = 0.15
BOX_REFLECTIVITY = 0.5


def beam_directions(azimuth_step_deg: float) -> np.ndarray:
    """``[F, 3]`` unit firing directions in the lidar frame (x forward, y left, z up)."""
    elevation = np.radians(np.linspace(-15.0, 15.0, N_BEAMS))
    azimuth = np.radians(np.arange(0.0, 360.0, azimuth_step_deg))
    el, az = np.meshgrid(elevation, azimuth, indexing="ij")
    return np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=-1).reshape(-1, 3)


def lidar_sweep(
    rng: np.random.Generator,
    enu_r_lidar: np.ndarray,
    position_enu: np.ndarray,
    boxes: BoxSet,
    azimuth_step_deg: float,
) -> tuple[np.ndarray, np.ndarray]:
    """One sweep.

    Parameters
    ----------
    enu_r_lidar, position_enu : numpy.ndarray
        True lidar pose: rotation ``[3, 3]`` (lidar -> ENU) and origin ``[3]``.
    boxes : BoxSet
        The world's boxes at the sweep time.

    Returns
    -------
    points_lidar : numpy.ndarray
        ``[P, 4]`` float32: x, y, z (lidar frame, metres), intensity (0-255).
    box_index : numpy.ndarray
        ``[P]`` int64 box hit by each return (:data:`~zendar_dataset.sim.raycast.GROUND` for the ground).
    """
    directions_lidar = beam_directions(azimuth_step_deg)
    distance, hit, normal = cast_rays(position_enu, rotate(enu_r_lidar, directions_lidar), boxes, MAX_RANGE_M)
    keep = hit != NOTHING
    directions_lidar, distance, hit, normal = directions_lidar[keep], distance[keep], hit[keep], normal[keep]
    measured = distance + rng.normal(0.0, RANGE_NOISE_M, distance.shape)
    incidence = np.abs(dot(rotate(enu_r_lidar, directions_lidar), normal))
    reflectivity = np.where(hit == GROUND, GROUND_REFLECTIVITY, BOX_REFLECTIVITY)
    intensity = np.clip(255.0 * reflectivity * incidence, 0.0, 255.0)
    points = np.concatenate([directions_lidar * measured[:, None], intensity[:, None]], axis=1)
    return points.astype(np.float32), hit
