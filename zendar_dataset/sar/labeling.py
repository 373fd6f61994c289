"""Labelling helpers: radar detections seen in a SAR image (paper §2.3).

The paper separates moving from static detections by projecting each radar
detection into the SAR image (which images mostly the static scene) and reading
the SAR SNR there: detections on moving objects tend to land on low-SNR pixels.
"""

from __future__ import annotations

import math

import numpy as np

from zendar_dataset.sar.grid import ImageGrid


def project_points(
    grid: ImageGrid,
    points: np.ndarray,
    *,
    max_out_of_plane_m: float = math.inf,
) -> tuple[np.ndarray, np.ndarray]:
    """Pixel coordinates of points (e.g. radar detections) in a SAR image.

    Parameters
    ----------
    grid : ImageGrid
        The image's grid.
    points : array_like, shape (N, 3)
        Points in the grid's frame, metres.
    max_out_of_plane_m : float
        Points farther than this from the image plane count as outside.

    Returns
    -------
    pixel_ij : numpy.ndarray, shape (N, 2), float64
        Fractional ``(i, j)`` of each point's projection onto the image plane.
    inside : numpy.ndarray, shape (N,), bool
        Whether the nearest pixel exists and the point is close enough to the plane.
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    i, j, out_of_plane_m = grid.world_to_pixel(points)
    height, width = grid.shape
    inside = (
        (np.rint(i) >= 0)
        & (np.rint(i) <= height - 1)
        & (np.rint(j) >= 0)
        & (np.rint(j) <= width - 1)
        & (np.abs(out_of_plane_m) <= max_out_of_plane_m)
    )
    return np.stack([i, j], axis=-1), inside


def noise_power(image: np.ndarray) -> float:
    """Robust noise floor of a SAR image: mean noise power ``E|n|²``.

    For complex Gaussian noise ``|n|²`` is exponential, whose median is
    ``E|n|²·ln 2``; the median ignores the (sparse) bright scatterers that would
    bias a mean. For a magnitude-only image pass the magnitudes: the estimate
    is the same.

    Parameters
    ----------
    image : array_like, shape (H, W), complex or real (magnitude)

    Returns
    -------
    float
        Estimated noise power, in the image's units squared.
    """
    power = np.abs(np.asarray(image)).astype(np.float64) ** 2
    return float(np.median(power) / math.log(2))


def local_snr_db(
    image: np.ndarray,
    pixel_ij: np.ndarray,
    *,
    radius_px: int = 2,
    noise: float | None = None,
) -> np.ndarray:
    """SAR SNR around pixels: peak power in a small window over the noise floor.

    Parameters
    ----------
    image : array_like, shape (H, W), complex or real (magnitude)
    pixel_ij : array_like, shape (N, 2)
        Fractional pixel coordinates (e.g. from :func:`project_points`); the window
        is centred on the nearest pixel.
    radius_px : int
        The window is ``(2·radius_px + 1)²`` pixels, clipped at the image border;
        one or two pixels absorb the projection error of a detection.
    noise : float, optional
        Noise power to divide by; default :func:`noise_power` of ``image``.

    Returns
    -------
    numpy.ndarray, shape (N,), float64
        ``10·log10(max |image|² in the window / noise)`` in dB; NaN for pixels
        whose nearest pixel is outside the image.
    """
    magnitude = np.abs(np.asarray(image))
    if magnitude.ndim != 2:
        raise ValueError(f"image must have shape (H, W), got {magnitude.shape}")
    pixel_ij = np.asarray(pixel_ij, dtype=np.float64).reshape(-1, 2)
    if radius_px < 0:
        raise ValueError(f"radius_px must be >= 0, got {radius_px}")
    noise = noise_power(magnitude) if noise is None else float(noise)
    height, width = magnitude.shape
    center = np.rint(pixel_ij).astype(np.int64)
    inside = (center[:, 0] >= 0) & (center[:, 0] < height) & (center[:, 1] >= 0) & (center[:, 1] < width)
    offsets = np.arange(-radius_px, radius_px + 1)
    # Windows for all detections at once: [N, K, K]; clipping repeats border pixels,
    # which leaves the maximum unchanged.
    rows = np.clip(center[:, 0, None, None] + offsets[None, :, None], 0, height - 1)
    cols = np.clip(center[:, 1, None, None] + offsets[None, None, :], 0, width - 1)
    peak = magnitude[rows, cols].reshape(len(center), -1).max(axis=1).astype(np.float64)
    with np.errstate(divide="ignore"):
        snr_db = 10 * np.log10(peak**2 / noise)
    return np.where(inside, snr_db, np.nan)


def snr_at_points_db(
    image: np.ndarray,
    grid: ImageGrid,
    points: np.ndarray,
    *,
    radius_px: int = 2,
    max_out_of_plane_m: float = math.inf,
    noise: float | None = None,
) -> np.ndarray:
    """SAR SNR (dB) at points in the grid's frame; NaN where they miss the image.

    Combines :func:`project_points` and :func:`local_snr_db` (see them for the
    arguments); ``points`` is (N, 3), the result (N,).
    """
    pixel_ij, inside = project_points(grid, points, max_out_of_plane_m=max_out_of_plane_m)
    snr_db = local_snr_db(image, pixel_ij, radius_px=radius_px, noise=noise)
    return np.where(inside, snr_db, np.nan)
