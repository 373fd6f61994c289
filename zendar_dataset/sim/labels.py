"""Moving-car labels (format v1 ``labels/moving_cars``) as an annotator would draw them from the radar data.

A car is labelled in a SAR frame when, at that frame's time,

- it moves faster than :data:`MIN_SPEED_MPS` over ground;
- its centre is ahead of the ego's front bumper (ego x > 0: nothing on or behind the ego) and
  inside at least one radar's field of view (azimuth within half of ``fov_azimuth_deg`` of the
  radar's boresight, range below the cube's maximum range);
- at least :data:`MIN_RADAR_SCATTERERS` of its scatterers are visible to that same radar: inside its
  field of view and range, with a clear line of sight (:func:`~zendar_dataset.sim.raycast.line_of_sight`,
  the ray casting the lidar and the radar returns use).

Positions, headings and velocities are in the true ego frame at the frame time.  Each row also says
how visible the car is, as nuScenes does with ``num_radar_pts``/``num_lidar_pts``:
``num_radar_scatterers`` (the most scatterers any one radar sees) and ``num_lidar_points`` (returns
on the car in the lidar sweep nearest in time).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from zendar_dataset.format.schema import LABEL_FIELD_NAMES
from zendar_dataset.sim import ego as ego_model
from zendar_dataset.sim.raycast import line_of_sight
from zendar_dataset.sim.rotate import unrotate
from zendar_dataset.sim.world import World

MIN_SPEED_MPS = 0.5
# An annotator places a box where the radar data show a car, not on a lone point: three returns
# are the fewest that make a cluster with an extent (a lone point or a pair is indistinguishable
# from a pole or a sidelobe); of a car's 15 modelled scatterers, a car seen side-on or end-on
# shows 4-9, one mostly hidden behind a parked car 1-3.
MIN_RADAR_SCATTERERS = 3
OPTIONAL_FIELDS = ("num_radar_scatterers", "num_lidar_points")


@dataclass(frozen=True)
class RadarView:
    """What a radar covers: mount in the ego frame, field of view and reach.

    Attributes
    ----------
    name : str
        Sensor name.
    fov_azimuth_deg : float
        Full horizontal field of view, degrees, centred on the boresight.
    max_range_m : float
        Farthest range the cube holds, metres.
    """

    name: str
    fov_azimuth_deg: float
    max_range_m: float

    def sees(self, points_sensor: np.ndarray) -> np.ndarray:
        """``[...]`` bool: points ``[..., 3]`` (sensor frame) inside the field of view and range."""
        azimuth = np.degrees(np.arctan2(points_sensor[..., 1], points_sensor[..., 0]))
        distance = np.linalg.norm(points_sensor, axis=-1)
        return (np.abs(azimuth) <= self.fov_azimuth_deg / 2) & (distance < self.max_range_m) & (distance > 0.3)


def radar_views(max_range_m: float) -> list[RadarView]:
    """The simulated radars' views (field of view from :data:`~zendar_dataset.sim.ego.RADAR_FOV_AZIMUTH_DEG`)."""
    return [RadarView(name, ego_model.RADAR_FOV_AZIMUTH_DEG, max_range_m) for name in ego_model.RADARS]


def visible_scatterers(world: World, ego, t_s: float, views: list[RadarView]) -> np.ndarray:
    """``[cars, radars]`` int64: each car's body scatterers each radar sees at ``t_s`` (scene seconds)."""
    t = np.array([float(t_s)])
    counts = np.zeros((len(world.cars), len(views)), np.int64)
    if not world.cars:
        return counts
    position, _velocity, _body, track_id = world.moving_scatterers(t)
    points = position[:, 0]
    boxes = world.boxes_at(float(t_s))
    track_index = {car.track_id: i for i, car in enumerate(world.cars)}
    rows = np.array([track_index[int(k)] for k in track_id])
    for j, view in enumerate(views):
        rotation, origin = ego_model.sensor_poses_enu(ego, view.name, np.array(float(t_s)))
        in_view = view.sees(unrotate(rotation, points - origin))
        clear = np.zeros(points.shape[0], bool)
        clear[in_view] = line_of_sight(origin, points[in_view], boxes)
        counts[:, j] = np.bincount(rows[clear], minlength=len(world.cars))
    return counts


def annotatable_cars(world: World, ego, t_s: float, views: list[RadarView]) -> list[tuple[int, int]]:
    """The cars an annotator labels at ``t_s`` (the rule of this module's docstring).

    Returns
    -------
    list of (int, int)
        Index into ``world.cars`` and the most scatterers any one radar sees of it, per labelled car.
    """
    t = np.array(float(t_s))
    rotation, translation = ego_model.enu_T_ego(ego, t)
    seen = visible_scatterers(world, ego, float(t_s), views)
    poses = [ego_model.sensor_poses_enu(ego, view.name, t) for view in views]
    out = []
    for i, car in enumerate(world.cars):
        velocity = car.trajectory.velocity_at(t)
        if np.hypot(velocity[0], velocity[1]) <= MIN_SPEED_MPS:
            continue
        center_enu = car.trajectory.position_at(t)
        if unrotate(rotation, center_enu - translation)[0] <= 0.0:
            continue
        labelled = False
        for j, (view, (sensor_rotation, origin)) in enumerate(zip(views, poses)):
            center_sensor = unrotate(sensor_rotation, center_enu + [0.0, 0.0, car.size_m[2] / 2] - origin)
            labelled |= bool(view.sees(center_sensor)) and seen[i, j] >= MIN_RADAR_SCATTERERS
        if labelled:
            out.append((i, int(seen[i].max())))
    return out


def label_rows(
    world: World,
    ego,
    times_s: np.ndarray,
    lidar_returns: dict[float, np.ndarray],
    timestamps_ns: list[int],
    views: list[RadarView],
) -> dict[str, np.ndarray]:
    """Label arrays (every field of format v1 plus :data:`OPTIONAL_FIELDS`) for the frames at ``times_s``.

    Parameters
    ----------
    times_s : numpy.ndarray
        ``[F]`` frame times, scene seconds; ``timestamps_ns`` their GPS stamps.
    lidar_returns : dict
        Lidar sweep time (scene seconds) -> returns per track id ``[n_tracks + 1]`` int64.
    views : list of RadarView
        The radars an annotator looks through.
    """
    rows: dict[str, list] = {name: [] for name in (*LABEL_FIELD_NAMES, *OPTIONAL_FIELDS)}
    sweep_times = np.array(sorted(lidar_returns))
    for t, stamp in zip(times_s, timestamps_ns):
        lidar_counts = lidar_returns[float(sweep_times[np.argmin(np.abs(sweep_times - t))])] if sweep_times.size else None
        rotation, translation = ego_model.enu_T_ego(ego, np.array(t))
        ego_yaw = float(np.arctan2(rotation[1, 0], rotation[0, 0]))
        for i, n_seen in annotatable_cars(world, ego, float(t), views):
            car = world.cars[i]
            velocity = car.trajectory.velocity_at(np.array(t))
            center_ego = unrotate(rotation, car.trajectory.position_at(np.array(t)) - translation)
            velocity_ego = unrotate(rotation, velocity)
            yaw = float(np.angle(np.exp(1j * (float(car.trajectory.yaw_at(np.array(t))) - ego_yaw))))
            n_lidar = int(lidar_counts[car.track_id]) if lidar_counts is not None and car.track_id < lidar_counts.size else 0
            for name, value in (("timestamp_ns", stamp), ("x", center_ego[0]), ("y", center_ego[1]),
                                ("length", car.size_m[0]), ("width", car.size_m[1]), ("yaw", yaw),
                                ("vx", velocity_ego[0]), ("vy", velocity_ego[1]), ("track_id", car.track_id),
                                ("num_radar_scatterers", n_seen), ("num_lidar_points", n_lidar)):
                rows[name].append(value)
    return {
        name: np.asarray(values, dtype=np.int64 if name in ("timestamp_ns", "track_id", *OPTIONAL_FIELDS) else np.float64)
        for name, values in rows.items()
    }
