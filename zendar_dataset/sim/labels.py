"""Moving-car labels (format v1 ``labels/moving_cars``) from the simulation's truth.

A car is labelled in a SAR frame when it moves faster than
:data:`MIN_SPEED_MPS` and the lidar sweep at (or nearest to) that frame has at
least :data:`MIN_LIDAR_RETURNS` returns on it, as the paper's lidar-based labels.
Positions, headings and velocities are in the true ego frame at the frame time.
"""

from __future__ import annotations

import numpy as np

from zendar_dataset.format.schema import LABEL_FIELD_NAMES
from zendar_dataset.sim import ego as ego_model
from zendar_dataset.sim.rotate import unrotate
from zendar_dataset.sim.world import World

MIN_SPEED_MPS = 0.5
MIN_LIDAR_RETURNS = 3


def label_rows(world: World, ego, times_s: np.ndarray, returns_per_sweep: dict[float, np.ndarray], timestamps_ns: list[int]) -> dict[str, np.ndarray]:
    """Label arrays for the frames at ``times_s`` (scene seconds) stamped ``timestamps_ns``.

    ``returns_per_sweep`` maps each lidar sweep time to the count of returns per track id.
    """
    rows: dict[str, list] = {name: [] for name in LABEL_FIELD_NAMES}
    sweep_times = np.array(sorted(returns_per_sweep))
    for t, stamp in zip(times_s, timestamps_ns):
        counts = returns_per_sweep[float(sweep_times[np.argmin(np.abs(sweep_times - t))])] if sweep_times.size else None
        rotation, translation = ego_model.enu_T_ego(ego, np.array(t))
        ego_yaw = float(np.arctan2(rotation[1, 0], rotation[0, 0]))
        for car in world.cars:
            velocity = car.trajectory.velocity_at(np.array(t))
            if np.hypot(velocity[0], velocity[1]) <= MIN_SPEED_MPS:
                continue
            if counts is None or counts[car.track_id] < MIN_LIDAR_RETURNS:
                continue
            center_ego = unrotate(rotation, car.trajectory.position_at(np.array(t)) - translation)
            velocity_ego = unrotate(rotation, velocity)
            yaw = float(np.angle(np.exp(1j * (float(car.trajectory.yaw_at(np.array(t))) - ego_yaw))))
            for name, value in (("timestamp_ns", stamp), ("x", center_ego[0]), ("y", center_ego[1]),
                                ("length", car.size_m[0]), ("width", car.size_m[1]), ("yaw", yaw),
                                ("vx", velocity_ego[0]), ("vy", velocity_ego[1]), ("track_id", car.track_id)):
                rows[name].append(value)
    return {
        name: np.asarray(values, dtype=np.int64 if name in ("timestamp_ns", "track_id") else np.float64)
        for name, values in rows.items()
    }
