"""Moving cars: ahead of the ego, oncoming, crossing and turning, with stops.

Cars on the road follow its reference line at a lane offset with their own
speed profile (cruise at 3-15 m/s, sometimes braking to a stop and pulling
away); crossing cars drive straight across the road at an intersection ahead;
turning cars come in from the side and turn into the oncoming lane.
"""

from __future__ import annotations

import numpy as np

from zendar_dataset.sim.trajectory import SAMPLE_INTERVAL_S, Trajectory, follow_path, speed_profile
from zendar_dataset.sim.world import LANE_WIDTH_M, MovingCar, Road, car_scatterers

KINDS = ("ahead", "oncoming", "crossing", "turning")


def _road_trajectory(road: Road, time_s: np.ndarray, speed: np.ndarray, s0: float, lateral: float, direction: float) -> Trajectory:
    dt = time_s[1] - time_s[0]
    travelled = np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * dt)])
    position, yaw = road.point(s0 + direction * travelled, lateral)
    if direction < 0:
        yaw = yaw + np.pi
    return Trajectory(time_s, position, yaw, speed)


def make_traffic(
    rng: np.random.Generator,
    road: Road,
    n_cars: int,
    t_start_s: float,
    duration_s: float,
    ego_s_at_start_m: float,
    ego_speed_mps: float,
) -> list[MovingCar]:
    """``n_cars`` moving cars around the ego's drive (track ids 1..n)."""
    cars = []
    for track_id in range(1, n_cars + 1):
        kind = KINDS[(track_id - 1) % len(KINDS)] if track_id <= len(KINDS) else str(rng.choice(KINDS))
        size = np.array([rng.uniform(4.0, 4.9), rng.uniform(1.7, 1.95), rng.uniform(1.4, 1.7)])
        cruise = float(rng.uniform(3.0, 15.0))
        stops = []
        if rng.random() < 0.25:
            stops.append((float(rng.uniform(0.3, 0.7) * duration_s), float(rng.uniform(0.5, 2.0))))
        time_s, speed = speed_profile(duration_s, cruise, stops)
        time_s = time_s + t_start_s
        if kind == "ahead":
            s0 = ego_s_at_start_m + rng.uniform(8.0, 40.0)
            trajectory = _road_trajectory(road, time_s, speed, s0, 0.0, 1.0)
        elif kind == "oncoming":
            s0 = ego_s_at_start_m + rng.uniform(20.0, 25.0 + (cruise + ego_speed_mps) * duration_s)
            trajectory = _road_trajectory(road, time_s, speed, s0, LANE_WIDTH_M, -1.0)
        else:
            s_cross = ego_s_at_start_m + rng.uniform(10.0, 30.0 + ego_speed_mps * duration_s)
            side = float(rng.choice([-1.0, 1.0]))
            lead = rng.uniform(0.3, 0.8) * cruise * duration_s
            start, road_yaw = road.point(s_cross + (LANE_WIDTH_M / 2 if side > 0 else 0.0), side * lead)
            heading = float(road_yaw) - side * np.pi / 2
            if kind == "crossing":
                kappa = lambda s: np.zeros_like(s)  # noqa: E731 - a one-line curvature profile
            else:
                radius = rng.uniform(6.0, 10.0)
                turn_start = lead - radius
                # Turn towards the road's far end: right when coming from the left side.
                sign = -side
                kappa = lambda s, a=turn_start, r=radius, g=sign: np.where(  # noqa: E731
                    (s > a) & (s < a + np.pi / 2 * r), g / r, 0.0
                )
            trajectory = follow_path(time_s, speed, start, heading, kappa)
        cars.append(MovingCar(track_id, trajectory, size, car_scatterers(rng, size)))
    return cars


__all__ = ["KINDS", "SAMPLE_INTERVAL_S", "make_traffic"]
