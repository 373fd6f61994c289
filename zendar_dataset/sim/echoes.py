"""What a radar receives from the moving cars: body scatterers with aspect-dependent RCS,
rolling wheel rims, and mirror ghosts off facades and guard rails.

:func:`car_echoes` is a drop-in for :meth:`zendar_dataset.sim.world.World.moving_scatterers`
seen from one radar position; with every effect off it returns exactly that.
"""

from __future__ import annotations

import numpy as np

from zendar_dataset.sim.imperfections import Imperfections, aspect_gain, surface_normals_body
from zendar_dataset.sim.multipath import ghost_pairs, mirror_points, mirrors_from_boxes
from zendar_dataset.sim.wheels import wheel_points
from zendar_dataset.sim.world import ScattererSet, World


def _body_normals_world(world: World, t_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Outward normals ``[S, 3]`` (ENU) and corner flags ``[S]`` of every car's body scatterers at ``t_s``."""
    normals, corners = [], []
    for car in world.cars:
        normal, corner = surface_normals_body(car.scatterers_body.position_m, car.size_m)
        yaw = float(car.trajectory.yaw_at(np.array(t_s)))
        c, s = np.cos(yaw), np.sin(yaw)
        normals.append(np.stack([c * normal[:, 0] - s * normal[:, 1], s * normal[:, 0] + c * normal[:, 1],
                                 np.zeros(normal.shape[0])], axis=1))
        corners.append(corner)
    if not normals:
        return np.zeros((0, 3)), np.zeros(0, bool)
    return np.concatenate(normals), np.concatenate(corners)


def car_echoes(
    world: World, t_s: np.ndarray, radar_enu: np.ndarray, settings: Imperfections, *, mid_index: int | None = None,
    reach_m: float | None = None,
) -> tuple[np.ndarray, np.ndarray, ScattererSet, np.ndarray]:
    """Moving-car returns seen from ``radar_enu`` ``[3]`` at times ``[M]``.

    Aspect gains and ghost geometry are evaluated once, at ``t_s[mid_index]`` (default:
    the middle time; a cube or a SAR aperture lasts a fraction of a second). With ``reach_m``,
    the effects are computed only for cars and mirrors that can matter within that range of the
    radar (a car's own echoes are returned for every car, as by ``World.moving_scatterers``).

    Returns
    -------
    position_enu, velocity_enu : numpy.ndarray
        ``[S, M, 3]`` metres and m/s.
    scatterers : ScattererSet
        RCS (aspect and reflection losses applied), fluctuation flags, phases; a ghost's
        ``owner_box`` is the static box it is seen in, which therefore does not hide it.
    track_id : numpy.ndarray
        ``[S]`` int64 (a ghost or a wheel carries its car's track id).
    """
    t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
    mid = t.shape[0] // 2 if mid_index is None else int(mid_index)
    radar = np.asarray(radar_enu, dtype=np.float64)
    position, velocity, body, track_id = world.moving_scatterers(t)
    normal, corner = _body_normals_world(world, float(t[mid]))
    rcs = body.rcs_m2 * aspect_gain(normal, radar[None, :] - position[:, mid], corner, settings)
    parts = [(position, velocity, ScattererSet(body.position_m, rcs, body.swerling1, body.phase_rad), track_id)]
    near_cars = world.cars
    if reach_m is not None:
        # A ghost is farther than its car, and a wheel is on it: far cars add neither.
        near_cars = [car for car in world.cars
                     if np.linalg.norm(car.trajectory.position_at(t[mid]) - radar) < reach_m + float(np.max(car.size_m))]
    wheels = wheel_points(near_cars, t, settings)
    if wheels[0].shape[0]:
        parts.append(wheels)
    if settings.multipath:
        all_position = np.concatenate([p[0] for p in parts])
        all_velocity = np.concatenate([p[1] for p in parts])
        all_set = ScattererSet.concatenate([p[2] for p in parts])
        all_ids = np.concatenate([p[3] for p in parts])
        all_normal = np.concatenate([normal, np.zeros((all_position.shape[0] - normal.shape[0], 3))])
        all_corner = np.concatenate([corner, np.zeros(all_position.shape[0] - corner.shape[0], bool)])
        mirrors = mirrors_from_boxes(world.static_boxes, settings, radar, reach_m)
        candidates = np.flatnonzero(np.isin(all_ids, [car.track_id for car in near_cars]))
        face, point = ghost_pairs(mirrors, radar, all_position[candidates, mid])
        point = candidates[point]
        if face.shape[0]:
            center, unit = mirrors.center_enu[face], mirrors.normal[face]
            ghost_position = mirror_points(all_position[point], center[:, None, :], unit[:, None, :])
            ghost_velocity = all_velocity[point] - 2.0 * np.sum(all_velocity[point] * unit[:, None, :], axis=-1, keepdims=True) * unit[:, None, :]
            # The car is seen from the radar's mirror image; its RCS from the unweighted body value.
            radar_image = mirror_points(radar[None, :], center, unit)
            base_rcs = np.concatenate([body.rcs_m2, all_set.rcs_m2[body.rcs_m2.shape[0]:]])[point]
            gain = aspect_gain(all_normal[point], radar_image - all_position[point, mid], all_corner[point], settings)
            ghost_rcs = base_rcs * gain * mirrors.reflection[face] ** 4
            ghosts = ScattererSet(np.zeros((face.shape[0], 3)), ghost_rcs, all_set.swerling1[point],
                                  all_set.phase_rad[point])
            ghosts.owner_box = mirrors.box_index[face]
            parts.append((ghost_position, ghost_velocity, ghosts, all_ids[point]))
    if len(parts) == 1:
        return parts[0]
    return (np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts]),
            ScattererSet.concatenate([p[2] for p in parts]), np.concatenate([p[3] for p in parts]))
