"""Moving cars: ahead of the ego, oncoming, crossing and turning, with stops.

Cars on the road follow its reference line in their lane with their own speed
profile (cruise at 3-15 m/s, sometimes braking to a stop and pulling away);
crossing cars drive straight across the road through an intersection (a cross
street the static world leaves clear), keeping to the right of their street;
turning cars come out of the cross street and turn into the oncoming lane.

A drawn car that would touch the ego, a static body or a car already placed at
any time of the scene is drawn again (at most :data:`MAX_DRAWS` times, then
left out), so no two bodies ever overlap: no car drives through the ego, a
parked car, a building or another car.
"""

from __future__ import annotations

import numpy as np

from zendar_dataset.sim.bodies import DEFAULT_MARGIN_M, boxes_overlap
from zendar_dataset.sim.trajectory import SAMPLE_INTERVAL_S, Trajectory, follow_path, follow_road, speed_profile
from zendar_dataset.sim.world import LANE_WIDTH_M, BoxSet, MovingCar, Road, car_scatterers

KINDS = ("ahead", "oncoming", "crossing", "turning")
MAX_DRAWS = 30
# Cars are checked against everything every CHECK_STEP_S: at the largest closing speed (~30 m/s,
# two cars at 15 m/s head on) they move 0.6 m in a step, the two bodies' margins together, so a
# contact between two checks still shows as an overlap of the grown boxes at the nearest one.
CHECK_STEP_S = 0.02


def _straight(s_m: np.ndarray) -> np.ndarray:
    """Zero curvature: a crossing car drives straight across the road."""
    return np.zeros_like(s_m)


def _quarter_turn(turn_start_m: float, radius_m: float, sign: float):
    """Curvature ``sign / radius_m`` over a quarter circle that starts ``turn_start_m`` along the path."""

    def curvature(s_m: np.ndarray) -> np.ndarray:
        return np.where((s_m > turn_start_m) & (s_m < turn_start_m + np.pi / 2 * radius_m), sign / radius_m, 0.0)

    return curvature


class _Occupancy:
    """Boxes of the bodies placed so far, at the check times ``[T]``."""

    def __init__(self, times_s: np.ndarray, ego_boxes: tuple[np.ndarray, np.ndarray, np.ndarray], static: BoxSet) -> None:
        self.times_s = times_s
        center, size, yaw = ego_boxes
        self.center = [center]  # each [T, 3]
        self.size = [np.broadcast_to(size, center.shape)]
        self.yaw = [yaw]
        self.static = static
        self._static_radius = 0.5 * np.hypot(static.size_m[:, 0], static.size_m[:, 1])

    def fits(self, center: np.ndarray, size: np.ndarray, yaw: np.ndarray) -> bool:
        """Whether a car at ``center [T, 3]``, ``size [3]``, ``yaw [T]`` keeps clear of every body."""
        radius = 0.5 * np.hypot(size[0], size[1]) + 2 * DEFAULT_MARGIN_M
        # The ego and other cars first (the likelier conflicts), then static bodies: a
        # bounding-circle test first, the exact test only on the few near pairs.
        others_c, others_s, others_y = np.stack(self.center), np.stack(self.size), np.stack(self.yaw)  # [K, T, ...]
        near = np.linalg.norm(others_c[..., :2] - center[None, :, :2], axis=-1) < radius + 0.5 * np.hypot(
            others_s[..., 0], others_s[..., 1]) + 2 * DEFAULT_MARGIN_M
        k_idx, t_idx = np.nonzero(near)
        if k_idx.size and np.any(boxes_overlap(
            center[t_idx], size, yaw[t_idx], others_c[k_idx, t_idx], others_s[k_idx, t_idx], others_y[k_idx, t_idx],
            DEFAULT_MARGIN_M,
        )):
            return False
        distance = np.linalg.norm(center[:, None, :2] - self.static.center_enu[None, :, :2], axis=-1)
        t_idx, b_idx = np.nonzero(distance < radius + self._static_radius[None, :])
        if t_idx.size and np.any(boxes_overlap(
            center[t_idx], size, yaw[t_idx], self.static.center_enu[b_idx], self.static.size_m[b_idx],
            self.static.yaw_rad[b_idx], DEFAULT_MARGIN_M,
        )):
            return False
        return True

    def add(self, center: np.ndarray, size: np.ndarray, yaw: np.ndarray) -> None:
        self.center.append(center)
        self.size.append(np.broadcast_to(size, center.shape))
        self.yaw.append(yaw)


def _draw_trajectory(
    rng: np.random.Generator,
    kind: str,
    road: Road,
    intersections_s: list[float],
    t_start_s: float,
    duration_s: float,
    ego_s_at_start_m: float,
    ego_speed_mps: float,
) -> Trajectory:
    cruise = float(rng.uniform(3.0, 15.0))
    if kind == "ahead":
        # The ego does not react to traffic: only a car at least as fast as the ego stays ahead of it.
        cruise = ego_speed_mps + float(rng.uniform(0.0, 4.0))
    stops = []
    # A car ahead that stopped would stop the ego too, which does not react to traffic.
    if rng.random() < 0.25 and kind != "ahead":
        stops.append((float(rng.uniform(0.3, 0.7) * duration_s), float(rng.uniform(0.5, 2.0))))
    time_s, speed = speed_profile(duration_s, cruise, stops)
    time_s = time_s + t_start_s
    if kind == "ahead":
        s0 = ego_s_at_start_m + rng.uniform(8.0, 40.0)
        return follow_road(road, time_s, speed, s0)
    if kind == "oncoming":
        s0 = ego_s_at_start_m + rng.uniform(20.0, 25.0 + (cruise + ego_speed_mps) * duration_s)
        return follow_road(road, time_s, speed, s0, lateral_m=LANE_WIDTH_M, against_road=True)
    s_cross = float(rng.choice(intersections_s))
    side = float(rng.choice([-1.0, 1.0]))  # +1: comes from the left of the road
    lead = float(rng.uniform(0.3, 0.8) * cruise * duration_s) + 2 * LANE_WIDTH_M
    # Keep to the right of the cross street: coming from the left (heading right), that is towards -s.
    start, road_yaw = road.point(s_cross - side * LANE_WIDTH_M / 2, LANE_WIDTH_M / 2 + side * lead)
    heading = float(road_yaw) - side * np.pi / 2
    if kind == "crossing":
        return follow_path(time_s, speed, start, heading, _straight)
    radius = float(rng.uniform(6.0, 10.0))
    # Turn into the oncoming lane (lateral LANE_WIDTH_M, heading against the road): right when
    # coming from the left, left when coming from the right; either way the turn carries the car
    # `radius` further across, so it starts that far before the lane.
    distance_to_lane = lead - side * LANE_WIDTH_M / 2
    return follow_path(time_s, speed, start, heading, _quarter_turn(distance_to_lane - radius, radius, -side))


def make_traffic(
    rng: np.random.Generator,
    road: Road,
    n_cars: int,
    t_start_s: float,
    duration_s: float,
    ego_s_at_start_m: float,
    ego_speed_mps: float,
    *,
    ego_boxes,
    static_boxes: BoxSet,
    intersections_s: list[float],
) -> list[MovingCar]:
    """Up to ``n_cars`` moving cars around the ego's drive (track ids 1..n in order of placement).

    Parameters
    ----------
    ego_boxes : callable
        ``times [T] -> (centres [T, 3], size [3], yaws [T])``, the ego's body (ENU).
    static_boxes : BoxSet
        The static world's boxes, which no car may touch.
    intersections_s : list of float
        Arc lengths of the cross streets, where crossing and turning cars drive.
    """
    times = np.arange(t_start_s, t_start_s + duration_s, CHECK_STEP_S)
    occupancy = _Occupancy(times, ego_boxes(times), static_boxes)
    cars = []
    for slot in range(1, n_cars + 1):
        kind = KINDS[(slot - 1) % len(KINDS)] if slot <= len(KINDS) else str(rng.choice(KINDS))
        for _draw in range(MAX_DRAWS):
            size = np.array([rng.uniform(4.0, 4.9), rng.uniform(1.7, 1.95), rng.uniform(1.4, 1.7)])
            trajectory = _draw_trajectory(rng, kind, road, intersections_s, t_start_s, duration_s, ego_s_at_start_m, ego_speed_mps)
            center = trajectory.position_at(times)
            center[:, 2] = size[2] / 2
            yaw = trajectory.yaw_at(times)
            if occupancy.fits(center, size, yaw):
                occupancy.add(center, size, yaw)
                cars.append(MovingCar(len(cars) + 1, trajectory, size, car_scatterers(rng, size)))
                break
    return cars


__all__ = ["KINDS", "SAMPLE_INTERVAL_S", "make_traffic"]
