"""Moving cars: ahead of the ego, oncoming, crossing and turning, with stops.

Cars on the road follow its reference line at a lane offset with their own
speed profile (cruise at 3-15 m/s, sometimes braking to a stop and pulling
away); crossing cars drive straight across the road at an intersection ahead;
turning cars come in from the side and turn into the oncoming lane.
"""

from __future__ import annotations

import numpy as np

from zendar_dataset.sim.trajectory import SAMPLE_INTERVAL_S, follow_path, follow_road, speed_profile
from zendar_dataset.sim.world import LANE_WIDTH_M, MovingCar, Road, car_scatterers

KINDS = ("ahead", "oncoming", "crossing", "turning")


def _straight(s_m: np.ndarray) -> np.ndarray:
    """Zero curvature: a crossing car drives straight across the road."""
    return np.zeros_like(s_m)


def _quarter_turn(turn_start_m: float, radius_m: float, sign: float):
    """Curvature ``sign / radius_m`` over a quarter circle that starts ``turn_start_m`` along the path."""

    def curvature(s_m: np.ndarray) -> np.ndarray:
        return np.where((s_m > turn_start_m) & (s_m < turn_start_m + np.pi / 2 * radius_m), sign / radius_m, 0.0)

    return curvature


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
            trajectory = follow_road(road, time_s, speed, s0)
        elif kind == "oncoming":
            s0 = ego_s_at_start_m + rng.uniform(20.0, 25.0 + (cruise + ego_speed_mps) * duration_s)
            trajectory = follow_road(road, time_s, speed, s0, lateral_m=LANE_WIDTH_M, against_road=True)
        else:
            s_cross = ego_s_at_start_m + rng.uniform(10.0, 30.0 + ego_speed_mps * duration_s)
            side = float(rng.choice([-1.0, 1.0]))
            lead = rng.uniform(0.3, 0.8) * cruise * duration_s
            start, road_yaw = road.point(s_cross + (LANE_WIDTH_M / 2 if side > 0 else 0.0), side * lead)
            heading = float(road_yaw) - side * np.pi / 2
            if kind == "crossing":
                curvature = _straight
            else:
                radius = rng.uniform(6.0, 10.0)
                # Turn towards the road's far end: right when coming from the left side.
                curvature = _quarter_turn(lead - radius, radius, -side)
            trajectory = follow_path(time_s, speed, start, heading, curvature)
        cars.append(MovingCar(track_id, trajectory, size, car_scatterers(rng, size)))
    return cars


__all__ = ["KINDS", "SAMPLE_INTERVAL_S", "make_traffic"]
