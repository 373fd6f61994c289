"""Which points lie behind the nearest obstacle seen from a viewpoint, in the horizontal plane."""

from __future__ import annotations

import numpy as np

from zendar_dataset.errors import ZendarError


def hidden_behind_obstacles(
    points_xy: np.ndarray, viewpoint_xy: np.ndarray, obstacles_xy: np.ndarray, *, margin_m: float, bin_rad: float,
) -> np.ndarray:
    """Points farther from the viewpoint than the nearest obstacle in their direction.

    Around the viewpoint, azimuth is cut into bins of ``bin_rad`` (wrapping at ±π); each bin's *first
    return* is its nearest obstacle. A point is hidden when its range exceeds by more than
    ``margin_m`` the first return of its own bin **and** of both neighbouring bins: one bin blocked is
    an obstacle's edge or a thin pole the point may be seen past, and a point's own direction is
    uncertain by about a bin. A bin without obstacles hides nothing.

    Parameters
    ----------
    points_xy : numpy.ndarray
        ``[N, 2]`` float64 metres, the points asked about.
    viewpoint_xy : numpy.ndarray
        ``[2]`` float64 metres, where they are seen from (same frame).
    obstacles_xy : numpy.ndarray
        ``[M, 2]`` float64 metres, points on obstacles (e.g. lidar returns above the ground).
    margin_m : float
        How far beyond the first returns a point must lie to be hidden (>= 0).
    bin_rad : float
        Azimuth bin width, radians (> 0).

    Returns
    -------
    numpy.ndarray
        ``[N]`` bool.

    Raises
    ------
    ZendarError
        On arrays of the wrong shape, or a negative margin or a bin that is not positive.
    """
    points_xy = np.asarray(points_xy, np.float64)
    obstacles_xy = np.asarray(obstacles_xy, np.float64)
    viewpoint_xy = np.asarray(viewpoint_xy, np.float64)
    problems = []
    if points_xy.ndim != 2 or points_xy.shape[1] != 2:
        problems.append(f"points_xy must be [N, 2], got shape {points_xy.shape}")
    if obstacles_xy.ndim != 2 or obstacles_xy.shape[1] != 2:
        problems.append(f"obstacles_xy must be [M, 2], got shape {obstacles_xy.shape}")
    if viewpoint_xy.shape != (2,):
        problems.append(f"viewpoint_xy must be [2], got shape {viewpoint_xy.shape}")
    if not margin_m >= 0:
        problems.append(f"margin_m must be >= 0, got {margin_m!r}")
    if not bin_rad > 0:
        problems.append(f"bin_rad must be > 0, got {bin_rad!r}")
    if problems:
        raise ZendarError("hidden_behind_obstacles: " + "; ".join(problems))
    hidden = np.zeros(points_xy.shape[0], bool)
    if points_xy.shape[0] == 0 or obstacles_xy.shape[0] == 0:
        return hidden
    n_bins = int(np.ceil(2.0 * np.pi / bin_rad))
    first_return_m = np.full(n_bins, np.inf)
    to_obstacles = obstacles_xy - viewpoint_xy
    np.minimum.at(first_return_m, _azimuth_bin(to_obstacles, bin_rad, n_bins), np.hypot(to_obstacles[:, 0], to_obstacles[:, 1]))
    to_points = points_xy - viewpoint_xy
    own = _azimuth_bin(to_points, bin_rad, n_bins)
    blocked_m = np.maximum(np.maximum(first_return_m[(own - 1) % n_bins], first_return_m[own]), first_return_m[(own + 1) % n_bins])
    return np.hypot(to_points[:, 0], to_points[:, 1]) > blocked_m + margin_m


def _azimuth_bin(offsets_xy: np.ndarray, bin_rad: float, n_bins: int) -> np.ndarray:
    return np.floor((np.arctan2(offsets_xy[:, 1], offsets_xy[:, 0]) + np.pi) / bin_rad).astype(np.int64) % n_bins
