"""Labelled car boxes projected into a radar's range-Doppler map: the cells each car can occupy.

A box (ego frame, at the cube's time) is sampled on a grid over its footprint. Each sample point is
placed in the map by its range from the radar's mount and its range rate relative to the radar:

    range_m = |p - m|,   range_rate_mps = (p - m) / |p - m| . (v_car - v_radar)

with ``m`` the radar's mount (``ego_T_sensor``), ``v_car`` the box's velocity over ground and
``v_radar`` the mount's velocity over ground including the ego's yaw rate
(:func:`~zendar_dataset.detection.locate.mount_velocity_ego`, the velocity the Doppler test uses).
Both are horizontal: labels are 2-D. Range bin ``round(range_m / range_bin_m)``; Doppler bin
``D // 2 + round(range_rate_mps / doppler_bin_mps)`` modulo ``D`` (the cube's convention: zero radial
velocity at ``D // 2``, positive when the range grows, ambiguous modulo ``D`` bins; checked against
:func:`~zendar_dataset.radar.fmcw.beat_signal_exact` in the tests).

The grid is half a range bin apart, so the sample points reach every range bin between the box's
nearest and farthest point; within a range bin the footprint spans every Doppler bin between its
points' lowest and highest (the Doppler of a near car changes by several bins across it, more than
between neighbouring sample points).

Points behind the radar (``x <= 0`` in its frame) or beyond the map's last range bin project
nothing. Points in front of the radar but outside its recorded field of view (``fov_azimuth_deg``)
are kept apart: the beam still reaches there (the simulator's and a real antenna's pattern falls
off past the quoted -3 dB edge, it does not stop), so their cells are neither a car nor background.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from zendar_dataset.detection import LabelBoxes, mount_velocity_ego
from zendar_dataset.errors import ZendarError
from zendar_dataset.geometry.frames import EgoPoses, ego_T_sensor
from zendar_dataset.radar import FmcwParams
from zendar_dataset.radar.cfar import cell_spacing


@dataclass(frozen=True)
class BoxFootprints:
    """The range-Doppler cells each box can occupy in one radar's map.

    Attributes
    ----------
    in_fov : numpy.ndarray
        ``[B, R, D]`` bool: cells of box ``b``'s points inside the radar's field of view and range.
    outside_fov : numpy.ndarray
        ``[B, R, D]`` bool: cells of its points in front of the radar but outside the field of view.
    """

    in_fov: np.ndarray
    outside_fov: np.ndarray


def _fov_azimuth_deg(calibration: Any) -> float | None:
    if isinstance(calibration, Mapping):
        return calibration.get("fov_azimuth_deg")
    return getattr(calibration, "fov_azimuth_deg", None)


def box_grid_points(boxes: LabelBoxes, index: int, spacing_m: float) -> np.ndarray:
    """``[P, 2]`` float64 points (ego frame, metres) on a grid over box ``index``, edges and corners included.

    Neighbouring points are at most ``spacing_m`` apart along the box's axes.
    """
    length, width = float(boxes.length[index]), float(boxes.width[index])
    along = np.linspace(-length / 2, length / 2, int(np.ceil(length / spacing_m)) + 1)
    across = np.linspace(-width / 2, width / 2, int(np.ceil(width / spacing_m)) + 1)
    a, c = (grid.reshape(-1) for grid in np.meshgrid(along, across, indexing="ij"))
    cos, sin = np.cos(boxes.yaw[index]), np.sin(boxes.yaw[index])
    return np.stack([boxes.x[index] + cos * a - sin * c, boxes.y[index] + sin * a + cos * c], axis=1)


def _fill_rows(out: np.ndarray, range_bin: np.ndarray, doppler_bin: np.ndarray) -> None:
    """Mark, per range bin, every Doppler bin from its points' lowest to highest (modulo ``D``)."""
    n_doppler = out.shape[1]
    for r in np.unique(range_bin).tolist():
        row = doppler_bin[range_bin == r]
        low, high = int(row.min()), int(row.max())
        if high - low + 1 >= n_doppler:
            out[r] = True
        else:
            out[r, np.arange(low, high + 1) % n_doppler] = True


def box_footprints(
    boxes_ego_at_cube_time: LabelBoxes, calibration: Any, poses: EgoPoses, timestamp_ns: int, n_range_bins: int,
    n_doppler_bins: int,
) -> BoxFootprints:
    """Project each box into one radar's ``[R, D]`` range-Doppler map (module docstring).

    Parameters
    ----------
    boxes_ego_at_cube_time : LabelBoxes
        Cars in the ego frame at the cube's time (:meth:`LabelBoxes.moved_to`), velocities over ground.
    calibration
        The radar's calibration record (waveform, mount, optional ``fov_azimuth_deg``).
    poses : EgoPoses
        The scene's ego poses (the radar's own velocity).
    timestamp_ns : int
        The cube's timestamp.
    n_range_bins, n_doppler_bins : int
        The cube's ``R`` and ``D``.

    Returns
    -------
    BoxFootprints
    """
    boxes = boxes_ego_at_cube_time
    shape = (len(boxes), int(n_range_bins), int(n_doppler_bins))
    in_fov, outside_fov = np.zeros(shape, bool), np.zeros(shape, bool)
    if len(boxes) == 0:
        return BoxFootprints(in_fov, outside_fov)
    fmcw = FmcwParams.from_calibration(calibration, n_samples=shape[1], n_chirps=shape[2])
    range_bin_m, doppler_bin_mps = cell_spacing(fmcw, shape[1], shape[2])
    fov_deg = _fov_azimuth_deg(calibration)
    if fov_deg is not None and not 0 < fov_deg <= 360:
        raise ZendarError(f"box_footprints: fov_azimuth_deg must lie in (0, 360], got {fov_deg!r}")
    ego_T_radar = ego_T_sensor(calibration)
    radar_T_ego = ego_T_radar.inverse()
    mount = np.asarray(ego_T_radar.translation, np.float64)
    radar_velocity_xy = mount_velocity_ego(poses, mount, int(timestamp_ns))[:2]
    for b in range(len(boxes)):
        points_xy = box_grid_points(boxes, b, float(range_bin_m) / 2)
        offset = points_xy - mount[:2]
        range_m = np.linalg.norm(offset, axis=1)
        line_of_sight = offset / np.maximum(range_m, 1e-9)[:, None]
        relative_velocity = np.array([boxes.vx[b], boxes.vy[b]]) - radar_velocity_xy
        range_rate_mps = line_of_sight @ relative_velocity
        range_bin = np.rint(range_m / range_bin_m).astype(np.int64)
        doppler_bin = shape[2] // 2 + np.rint(range_rate_mps / doppler_bin_mps).astype(np.int64)
        # At the mount's height: only the direction in the radar's horizontal plane matters.
        points_radar = radar_T_ego.transform_points(np.column_stack([points_xy, np.full(len(points_xy), mount[2])]))
        azimuth_deg = np.degrees(np.arctan2(points_radar[:, 1], points_radar[:, 0]))
        reached = (points_radar[:, 0] > 0) & (range_bin < shape[1])
        seen = reached if fov_deg is None else reached & (np.abs(azimuth_deg) <= fov_deg / 2)
        _fill_rows(in_fov[b], range_bin[seen], doppler_bin[seen])
        _fill_rows(outside_fov[b], range_bin[reached & ~seen], doppler_bin[reached & ~seen])
    return BoxFootprints(in_fov, outside_fov)


__all__ = ["BoxFootprints", "box_footprints", "box_grid_points"]
