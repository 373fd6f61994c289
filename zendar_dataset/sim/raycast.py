"""Ray casting against oriented boxes and the ground plane: what each sensor can see.

One world, one geometry for every sensor: the lidar and the camera cast rays
(:func:`cast_rays`, first hit), the radars ask whether the straight path to each
point scatterer is clear (:func:`line_of_sight`), both with the same slab test
against the same boxes, so a car hidden behind a wall is hidden from both.
Numba kernels run the slab test of every ray against every box: the numpy
version needs ``[boxes, rays, 3]`` temporaries and was ~10x slower for camera
frames (tens of thousands of rays against a few hundred boxes).
"""

from __future__ import annotations

import numba
import numpy as np

from zendar_dataset.sim.world import BoxSet

GROUND = -1
NOTHING = -2


@numba.njit(cache=True, inline="always")
def _slab(ox, oy, oz, dx, dy, dz, c, s, half_size):  # pragma: no cover - compiled
    """The line ``o + t·d`` (box-centred ENU) against one box of yaw (cos c, sin s), half sizes ``half_size``.

    Returns ``(t_near, t_far, axis, sign)``: the parameter interval inside the box (empty when
    ``t_near > t_far``), the box axis of the entry face and its outward sign.
    """
    # Into the box frame (rotate by -yaw).
    lox, loy = c * ox + s * oy, -s * ox + c * oy
    ldx, ldy = c * dx + s * dy, -s * dx + c * dy
    t_near, t_far, axis, sign = -np.inf, np.inf, -1, 0.0
    for k in range(3):
        o = lox if k == 0 else (loy if k == 1 else oz)
        d = ldx if k == 0 else (ldy if k == 1 else dz)
        h = half_size[k]
        if abs(d) < 1e-12:
            if o < -h or o > h:
                return np.inf, -np.inf, -1, 0.0
            continue
        t1, t2 = (-h - o) / d, (h - o) / d
        face = -1.0
        if t1 > t2:
            t1, t2, face = t2, t1, 1.0
        if t1 > t_near:
            t_near, axis, sign = t1, k, face
        if t2 < t_far:
            t_far = t2
    return t_near, t_far, axis, sign


@numba.njit(cache=True)
def _cast(origin, directions, centers, half_sizes, cos_yaw, sin_yaw, max_range):  # pragma: no cover - compiled
    n_rays = directions.shape[0]
    distance = np.full(n_rays, np.inf)
    hit = np.full(n_rays, -2, dtype=np.int64)
    normal = np.zeros((n_rays, 3))
    for r in range(n_rays):
        dx, dy, dz = directions[r, 0], directions[r, 1], directions[r, 2]
        best = max_range
        best_box = -2
        nx, ny, nz = 0.0, 0.0, 0.0
        if dz < -1e-12:
            t = -origin[2] / dz
            if 0.0 < t < best:
                best, best_box, nx, ny, nz = t, -1, 0.0, 0.0, 1.0
        for b in range(centers.shape[0]):
            c, s = cos_yaw[b], sin_yaw[b]
            t_near, t_far, axis, sign = _slab(
                origin[0] - centers[b, 0], origin[1] - centers[b, 1], origin[2] - centers[b, 2],
                dx, dy, dz, c, s, half_sizes[b],
            )
            if t_near > t_far or t_near <= 0.0 or t_near >= best:
                continue
            best, best_box = t_near, b
            lx = sign if axis == 0 else 0.0
            ly = sign if axis == 1 else 0.0
            nx, ny, nz = c * lx - s * ly, s * lx + c * ly, (sign if axis == 2 else 0.0)
        if best_box != -2:
            distance[r] = best
            hit[r] = best_box
            normal[r, 0], normal[r, 1], normal[r, 2] = nx, ny, nz
    return distance, hit, normal


def cast_rays(
    origin_enu: np.ndarray, directions_enu: np.ndarray, boxes: BoxSet, max_range_m: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """First hit of each ray from one origin.

    Parameters
    ----------
    origin_enu : numpy.ndarray
        ``[3]`` ray origin, ENU metres.
    directions_enu : numpy.ndarray
        ``[R, 3]`` unit directions, ENU.
    boxes : BoxSet
        Obstacles; the ground is the plane ``z = 0``.
    max_range_m : float
        Rays travelling further hit nothing.

    Returns
    -------
    distance_m : numpy.ndarray
        ``[R]`` float64 (``inf`` where nothing is hit).
    hit : numpy.ndarray
        ``[R]`` int64: box index, :data:`GROUND` or :data:`NOTHING`.
    normal_enu : numpy.ndarray
        ``[R, 3]`` outward unit normal of the surface hit.
    """
    origin = np.ascontiguousarray(origin_enu, dtype=np.float64)
    # Only boxes that can be reached matter.
    reach = np.linalg.norm(boxes.center_enu - origin, axis=1) - 0.5 * np.linalg.norm(boxes.size_m, axis=1)
    keep = np.flatnonzero(reach < max_range_m)
    distance, hit, normal = _cast(
        origin,
        np.ascontiguousarray(directions_enu, dtype=np.float64),
        np.ascontiguousarray(boxes.center_enu[keep]),
        np.ascontiguousarray(boxes.size_m[keep] / 2),
        np.cos(boxes.yaw_rad[keep]),
        np.sin(boxes.yaw_rad[keep]),
        float(max_range_m),
    )
    mapped = np.where(hit >= 0, keep[np.maximum(hit, 0)] if keep.size else hit, hit)
    return distance, mapped, normal


# A scatterer on a box's surface (a car's corner, bumper or side) is seen unless the path enters
# that box more than this far before reaching it; rounding puts surface points within ~1e-12 m of
# the face, and 1 cm is far below any feature the sensors resolve.
SURFACE_TOLERANCE_M = 0.01


@numba.njit(cache=True)
def _clear(origin, points, owner, centers, half_sizes, cos_yaw, sin_yaw, tolerance):  # pragma: no cover - compiled
    n_points = points.shape[0]
    clear = np.ones(n_points, dtype=np.bool_)
    for p in range(n_points):
        dx, dy, dz = points[p, 0] - origin[0], points[p, 1] - origin[1], points[p, 2] - origin[2]
        length = np.sqrt(dx * dx + dy * dy + dz * dz)
        if length <= tolerance:
            continue
        # Parametrise the segment by distance from the origin: t in [0, length].
        dx, dy, dz = dx / length, dy / length, dz / length
        for b in range(centers.shape[0]):
            if b == owner[p]:
                continue
            t_near, t_far, _, _ = _slab(
                origin[0] - centers[b, 0], origin[1] - centers[b, 1], origin[2] - centers[b, 2],
                dx, dy, dz, cos_yaw[b], sin_yaw[b], half_sizes[b],
            )
            if max(t_near, 0.0) < min(t_far, length - tolerance):
                clear[p] = False
                break
    return clear


def line_of_sight(origin_enu: np.ndarray, points_enu: np.ndarray, boxes: BoxSet, owner_box: np.ndarray | None = None) -> np.ndarray:
    """Whether the straight path from ``origin_enu`` to each point is clear of every box.

    Parameters
    ----------
    origin_enu : numpy.ndarray
        ``[3]`` sensor position, ENU metres.
    points_enu : numpy.ndarray
        ``[P, 3]`` scatterer positions, ENU metres.
    boxes : BoxSet
        Obstacles (static and moving, at the time of the look).
    owner_box : numpy.ndarray, optional
        ``[P]`` int64 index into ``boxes`` of a box that does not hide the point (the wall a facade
        scatterer sits in, the pole it is on); -1 for none.

    Returns
    -------
    numpy.ndarray
        ``[P]`` bool: no box is entered on the way, except within :data:`SURFACE_TOLERANCE_M` of the
        point, so a car's scatterers on the side facing the sensor are seen and those on the far
        side are hidden by the car itself.  The ground does not hide points above it.
    """
    origin = np.ascontiguousarray(origin_enu, dtype=np.float64)
    points = np.ascontiguousarray(points_enu, dtype=np.float64).reshape(-1, 3)
    owner = np.full(points.shape[0], -1, np.int64) if owner_box is None else np.asarray(owner_box, np.int64)
    if not points.shape[0] or not boxes.center_enu.shape[0]:
        return np.ones(points.shape[0], bool)
    # Only boxes nearer than the farthest point can be in the way.
    reach = float(np.max(np.linalg.norm(points - origin, axis=1)))
    gap = np.linalg.norm(boxes.center_enu - origin, axis=1) - 0.5 * np.linalg.norm(boxes.size_m, axis=1)
    keep = np.flatnonzero(gap < reach)
    # Owners refer to the full box list: map them onto the kept boxes (-1 where culled).
    position = np.full(boxes.center_enu.shape[0] + 1, -1, np.int64)
    position[keep] = np.arange(keep.size)
    owner_kept = np.where(owner >= 0, position[np.maximum(owner, 0)], -1)
    return _clear(
        origin, points, owner_kept,
        np.ascontiguousarray(boxes.center_enu[keep]), np.ascontiguousarray(boxes.size_m[keep] / 2),
        np.cos(boxes.yaw_rad[keep]), np.sin(boxes.yaw_rad[keep]), SURFACE_TOLERANCE_M,
    )
