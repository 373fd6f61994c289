"""Wheel micro-Doppler: rim points that roll with each moving car.

A wheel of rolling radius ``r`` on a car at speed ``v`` turns at ``v / r``; a
point on its rim moves over the ground at anything from 0 (touching the road)
to ``2 v`` (at the top), so the car's Doppler line gets a spread of weaker
returns around it that changes from chirp to chirp.  Each wheel carries two rim
points half a turn apart (tread and rim features), at the wheel-house positions
of :func:`zendar_dataset.sim.world.car_scatterers`.
"""

from __future__ import annotations

import numpy as np

from zendar_dataset.sim.imperfections import Imperfections
from zendar_dataset.sim.world import MovingCar, ScattererSet

WHEELBASE_FRACTION = 0.6  # axle at 0.6 half-lengths from the centre: the wheel houses of car_scatterers
POINTS_PER_WHEEL = 2


def wheel_hubs_body(size_m: np.ndarray, radius_m: float) -> np.ndarray:
    """``[4, 3]`` hub positions of a car's wheels in its body frame (outer face of each wheel)."""
    half_l, half_w = 0.5 * float(size_m[0]), 0.5 * float(size_m[1])
    return np.array([[sx * WHEELBASE_FRACTION * half_l, sy * half_w, radius_m] for sx in (1, -1) for sy in (1, -1)])


def rolled_angle_rad(car: MovingCar, t_s: np.ndarray, radius_m: float) -> np.ndarray:
    """How far the car's wheels have turned at ``t_s`` ``[M]``: travelled distance / radius."""
    trajectory = car.trajectory
    speed = trajectory.speed_mps
    travelled = np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(trajectory.time_s))])
    return np.interp(t_s, trajectory.time_s, travelled) / radius_m


def wheel_points(
    cars: list[MovingCar], t_s: np.ndarray, settings: Imperfections
) -> tuple[np.ndarray, np.ndarray, ScattererSet, np.ndarray]:
    """Rim points of every car's wheels at times ``[M]``.

    Returns positions and velocities ``[W, M, 3]`` (ENU), their scatterers (steady,
    ``wheel_rcs_m2`` each; ``position_m`` unused, zeros) and track ids ``[W]``.
    """
    t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
    if not settings.wheel_micro_doppler or not cars:
        empty = np.zeros((0, t.shape[0], 3))
        return empty, empty, ScattererSet.empty(), np.zeros(0, np.int64)
    r = settings.wheel_radius_m
    positions, velocities, ids = [], [], []
    for car in cars:
        hubs = wheel_hubs_body(car.size_m, r)  # [4, 3]
        theta = rolled_angle_rad(car, t, r)  # [M]
        angles = theta[None, :] + (np.arange(POINTS_PER_WHEEL) * 2 * np.pi / POINTS_PER_WHEEL)[:, None]  # [K, M]
        # Angle from the top, rolling forward: (r sin, 0, r cos) relative to the hub, body frame.
        rim_x, rim_z = r * np.sin(angles), r * np.cos(angles)
        body_x = hubs[:, None, None, 0] + rim_x[None]  # [4, K, M]
        body_y = np.broadcast_to(hubs[:, None, None, 1], body_x.shape)
        body_z = hubs[:, None, None, 2] + rim_z[None]
        yaw = car.trajectory.yaw_at(t)
        c, s = np.cos(yaw), np.sin(yaw)
        origin = car.trajectory.position_at(t)  # [M, 3]
        x = origin[:, 0] + c * body_x - s * body_y
        y = origin[:, 1] + s * body_x + c * body_y
        pos = np.stack([x, y, body_z], axis=-1).reshape(-1, t.shape[0], 3)
        # Velocity: the body's rigid motion plus the rim's motion about the hub.
        body_velocity = car.trajectory.velocity_at(t)  # [M, 3]
        speed = np.linalg.norm(body_velocity, axis=-1)
        rate = car.trajectory.yaw_rate_at(t)
        spin = speed / r
        rim_vx, rim_vz = spin * rim_z, -spin * rim_x  # d/dt of (r sin, r cos)
        rel_x, rel_y = c * body_x - s * body_y, s * body_x + c * body_y
        vel_x = body_velocity[:, 0] - rate * rel_y + c * rim_vx
        vel_y = body_velocity[:, 1] + rate * rel_x + s * rim_vx
        vel = np.stack([vel_x, vel_y, np.broadcast_to(rim_vz, vel_x.shape)], axis=-1).reshape(-1, t.shape[0], 3)
        positions.append(pos)
        velocities.append(vel)
        ids.append(np.full(pos.shape[0], car.track_id, dtype=np.int64))
    n = sum(p.shape[0] for p in positions)
    # A rim feature's reflection phase is fixed by where it sits on the wheel: spread evenly.
    phase = np.mod(np.arange(n) * 2.399963, 2 * np.pi)
    scatterers = ScattererSet(np.zeros((n, 3)), np.full(n, settings.wheel_rcs_m2), np.zeros(n, bool), phase)
    return np.concatenate(positions), np.concatenate(velocities), scatterers, np.concatenate(ids)
