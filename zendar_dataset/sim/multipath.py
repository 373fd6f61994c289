"""First-order multipath: mirror ghosts of moving cars off building facades and guard rails.

A radar wave that goes to a flat wall, on to a car and back the same way
(radar -> wall -> car -> wall -> radar) travels exactly as far as a straight
path to the car's mirror image behind the wall, and arrives from the
direction of that image: the radar sees a *ghost* car at the mirror position,
moving like the mirror of the car, weakened by the wall's amplitude reflection
coefficient twice (``|Γ|⁴`` in power).  A ghost exists while the specular point
(where the radar-to-ghost line crosses the wall plane) lies on the wall.

The vertical faces of every facade and guard-rail box are the mirrors.  Ghosts
of static objects would be static too (they fall inside the buildings and are
masked like any static return), so only moving cars' scatterers are mirrored.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from zendar_dataset.sim.imperfections import Imperfections
from zendar_dataset.sim.world import COLORS, BoxSet


@dataclass(frozen=True)
class Mirrors:
    """Vertical reflecting faces.

    Attributes
    ----------
    center_enu : numpy.ndarray
        ``[F, 3]`` centre of each face's ground line (z = 0), metres.
    normal : numpy.ndarray
        ``[F, 3]`` outward horizontal unit normal.
    along : numpy.ndarray
        ``[F, 3]`` horizontal unit vector along the face.
    half_length_m, height_m : numpy.ndarray
        ``[F]`` half the face's length and its top above the ground, metres.
    bottom_m : numpy.ndarray
        ``[F]`` its bottom above the ground (a rail hangs above it), metres.
    reflection : numpy.ndarray
        ``[F]`` amplitude reflection coefficient ``|Γ|``.
    box_index : numpy.ndarray
        ``[F]`` int64 index of the face's box in the ``BoxSet`` it came from.
    """

    center_enu: np.ndarray
    normal: np.ndarray
    along: np.ndarray
    half_length_m: np.ndarray
    height_m: np.ndarray
    bottom_m: np.ndarray
    reflection: np.ndarray
    box_index: np.ndarray


def mirrors_from_boxes(boxes: BoxSet, settings: Imperfections, radar_enu: np.ndarray | None = None,
                       reach_m: float | None = None) -> Mirrors:
    """The four vertical faces of every facade (building) and guard-rail box in ``boxes``
    (with ``radar_enu`` and ``reach_m``: only boxes that come within ``reach_m`` of the radar)."""
    color = boxes.color.astype(np.int64)
    is_building = np.all(color == np.array(COLORS["building"]), axis=1)
    is_rail = np.all(color == np.array(COLORS["rail"]), axis=1)
    keep = is_building | is_rail
    if radar_enu is not None and reach_m is not None:
        half_diagonal = 0.5 * np.hypot(boxes.size_m[:, 0], boxes.size_m[:, 1])
        keep &= np.hypot(*(boxes.center_enu[:, :2] - np.asarray(radar_enu)[:2]).T) < reach_m + half_diagonal
    index = np.flatnonzero(keep)
    yaw = boxes.yaw_rad[index]
    zero = np.zeros(index.size)
    length_axis = np.stack([np.cos(yaw), np.sin(yaw), zero], axis=1)  # [B, 3]
    width_axis = np.stack([-np.sin(yaw), np.cos(yaw), zero], axis=1)
    length, width, height = (boxes.size_m[index, k] for k in range(3))
    ground = boxes.center_enu[index] * np.array([1.0, 1.0, 0.0])
    # Faces in the order: +width, -width, +length, -length (axis 1), flattened box-major.
    normal = np.stack([width_axis, -width_axis, length_axis, -length_axis], axis=1)  # [B, 4, 3]
    along = np.stack([length_axis, length_axis, width_axis, width_axis], axis=1)
    offset = np.stack([width / 2, width / 2, length / 2, length / 2], axis=1)  # [B, 4]
    half = np.stack([length / 2, length / 2, width / 2, width / 2], axis=1)
    top = np.repeat((boxes.center_enu[index, 2] + height / 2)[:, None], 4, axis=1)
    bottom = np.repeat((boxes.center_enu[index, 2] - height / 2)[:, None], 4, axis=1)
    gamma = np.where(is_rail[index], settings.rail_reflection, settings.facade_reflection)
    return Mirrors(
        (ground[:, None, :] + normal * offset[..., None]).reshape(-1, 3), normal.reshape(-1, 3), along.reshape(-1, 3),
        half.reshape(-1), top.reshape(-1), bottom.reshape(-1), np.repeat(gamma, 4), np.repeat(index, 4).astype(np.int64),
    )


def mirror_points(points: np.ndarray, center: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Reflections of ``points [..., 3]`` in the plane through ``center [3]`` with unit normal ``normal [3]``."""
    distance = np.sum((points - center) * normal, axis=-1, keepdims=True)
    return points - 2.0 * distance * normal


def ghost_pairs(mirrors: Mirrors, radar_enu: np.ndarray, points_enu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Which (face, point) pairs make a ghost: ``(face index [G], point index [G])``.

    Both the radar and the point must be in front of the face, and the line from the
    radar to the point's mirror image must cross the face's plane on the face.
    """
    if mirrors.center_enu.shape[0] == 0 or points_enu.shape[0] == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    radar = np.asarray(radar_enu, dtype=np.float64)
    radar_side = np.sum((radar - mirrors.center_enu) * mirrors.normal, axis=1)  # [F]
    point_side = np.sum((points_enu[None, :, :] - mirrors.center_enu[:, None, :]) * mirrors.normal[:, None, :], axis=2)  # [F, S]
    ghost = points_enu[None, :, :] - 2.0 * point_side[..., None] * mirrors.normal[:, None, :]
    # The radar-to-ghost segment crosses the plane at fraction radar_side / (radar_side + point_side).
    fraction = radar_side[:, None] / np.maximum(radar_side[:, None] + point_side, 1e-9)
    crossing = radar[None, None, :] + fraction[..., None] * (ghost - radar[None, None, :])
    offset_along = np.sum((crossing - mirrors.center_enu[:, None, :]) * mirrors.along[:, None, :], axis=2)
    valid = (
        (radar_side[:, None] > 0.0) & (point_side > 0.0)
        & (np.abs(offset_along) <= mirrors.half_length_m[:, None])
        & (crossing[..., 2] >= mirrors.bottom_m[:, None]) & (crossing[..., 2] <= mirrors.height_m[:, None])
    )
    face, point = np.nonzero(valid)
    return face.astype(np.int64), point.astype(np.int64)
