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


def mirrors_from_boxes(boxes: BoxSet, settings: Imperfections) -> Mirrors:
    """The four vertical faces of every facade (building) and guard-rail box in ``boxes``."""
    color = boxes.color.astype(np.int64)
    is_building = np.all(color == np.array(COLORS["building"]), axis=1)
    is_rail = np.all(color == np.array(COLORS["rail"]), axis=1)
    index = np.flatnonzero(is_building | is_rail)
    centers, normals, alongs, half_lengths, tops, bottoms, reflections, owners = [], [], [], [], [], [], [], []
    for b in index:
        yaw = float(boxes.yaw_rad[b])
        length_axis = np.array([np.cos(yaw), np.sin(yaw), 0.0])
        width_axis = np.array([-np.sin(yaw), np.cos(yaw), 0.0])
        length, width, height = boxes.size_m[b]
        ground = boxes.center_enu[b] * np.array([1.0, 1.0, 0.0])
        top = float(boxes.center_enu[b, 2] + height / 2)
        bottom = float(boxes.center_enu[b, 2] - height / 2)
        gamma = settings.rail_reflection if is_rail[b] else settings.facade_reflection
        for normal, along, offset, half in (
            (width_axis, length_axis, width / 2, length / 2), (-width_axis, length_axis, width / 2, length / 2),
            (length_axis, width_axis, length / 2, width / 2), (-length_axis, width_axis, length / 2, width / 2),
        ):
            centers.append(ground + normal * offset)
            normals.append(normal)
            alongs.append(along)
            half_lengths.append(half)
            tops.append(top)
            bottoms.append(bottom)
            reflections.append(gamma)
            owners.append(b)
    if not centers:
        empty = np.zeros((0, 3))
        return Mirrors(empty, empty, empty, np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0, np.int64))
    return Mirrors(np.array(centers), np.array(normals), np.array(alongs), np.array(half_lengths), np.array(tops),
                   np.array(bottoms), np.array(reflections), np.array(owners, dtype=np.int64))


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
