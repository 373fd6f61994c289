"""Where a radar cannot see: its shadow behind static obstacles, measured by the scene's lidar.

The SAR static-scene test reads a point as dynamic when the SAR image is dark where the point lies
(:mod:`zendar_dataset.detection.static_scene`). Behind a building's facade or a wall the image is
dark for another reason: the radar does not see there, so no static scatterer lights that place.
What the radar reports there is not a return from that place but a multipath *ghost* of a moving
car (the path radar → wall → car → wall → radar reads as a car behind the wall,
:mod:`zendar_dataset.sim.multipath`): the dark image would call it dynamic, and it is no car. A
point in the radar's shadow is one the SAR image cannot judge, as a point outside every image.

The lidar measures that shadow: from its sweep nearest the point's time, every return between
:data:`OBSTACLE_HEIGHTS_M` above the ego's ground plane (cars, walls, poles; not the road) is an
obstacle, and a point lies in the shadow when it is more than a margin beyond the nearest obstacle
in its direction from the radar (:func:`zendar_dataset.geometry.occlusion.hidden_behind_obstacles`).
A lidar sees in straight lines as the radar does, from a few metres away on the same car; a scene
without lidar, or a time without a sweep within :data:`MAX_SWEEP_GAP_NS`, has no measured shadow
and hides nothing.
"""

from __future__ import annotations

import functools

import numpy as np

from zendar_dataset.geometry.frames import EgoPoses, ego_T_sensor
from zendar_dataset.geometry.occlusion import hidden_behind_obstacles
from zendar_dataset.geometry.se3 import SE3

#: Lidar returns this high above the ego's ground plane (its z = 0) are obstacles: above the road's
#: returns (and kerbs) and up to a tall vehicle; the ego frame's origin is on the ground.
OBSTACLE_HEIGHTS_M = (0.3, 3.0)
#: Azimuth bins of the first-return map: about the lidar's horizontal spacing at the demo's 10,000
#: points per sweep over its lowest rings, and a radar point's DOA error at mid range.
SHADOW_BIN_RAD = float(np.deg2rad(0.5))
#: The lidar turns at 10 Hz: the nearest sweep is at most 50 ms away; farther means none was recorded.
MAX_SWEEP_GAP_NS = 150_000_000


class RadarShadow:
    """The scene's lidar obstacles and which points lie in a radar's shadow behind them.

    Each lidar's sweeps are read in one go at first use and their obstacles kept, each sweep's in the
    ego frame of its own time: the test runs once per radar cube, and a kept scene is tested again by
    every pass over it. A 1 s demo-short scene holds about 100,000 lidar points (1.6 MB); a 30 s scene
    of the paper profile at most 300 sweeps of 28,800 rays (138 MB read once, its obstacles a part).

    Parameters
    ----------
    reader : SceneReader
        The scene; every ``lidar`` sensor's sweeps are obstacles.
    """

    def __init__(self, reader) -> None:
        self._reader = reader
        self.sensors = reader.sensors("lidar")
        self.timestamps = {s: np.asarray(reader.timestamps(f"lidar/{s}"), np.int64) for s in self.sensors}
        self._obstacles: dict[str, list[np.ndarray]] = {}
        self._ecef_T_ego: dict[int, SE3] = {}

    @classmethod
    def of(cls, reader) -> RadarShadow | None:
        """The scene's shadow, or None when it has no lidar."""
        return cls(reader) if reader.sensors("lidar") else None

    @functools.cached_property
    def poses(self) -> EgoPoses:
        return self._reader.ego_poses()

    def _pose(self, timestamp_ns: int) -> SE3:
        """The ego pose at a time, memoised: every pass asks for the same cube and sweep times."""
        if timestamp_ns not in self._ecef_T_ego:
            self._ecef_T_ego[timestamp_ns] = self.poses.ecef_T_ego(timestamp_ns)
        return self._ecef_T_ego[timestamp_ns]

    def sweep_obstacles(self, sensor: str) -> list[np.ndarray]:
        """Per sweep of ``sensor``, ``[M, 3]`` float64 obstacles in the ego frame at the sweep's time, metres."""
        if sensor not in self._obstacles:
            points, offsets = self._reader.lidar_sweeps(sensor)
            points_ego = ego_T_sensor(self._reader.calibration.sensors[sensor]).transform_points(np.asarray(points[:, :3], np.float64))
            low, high = OBSTACLE_HEIGHTS_M
            obstacle = (points_ego[:, 2] > low) & (points_ego[:, 2] < high)
            kept_before = np.concatenate([[0], np.cumsum(obstacle)])[offsets]  # obstacles before each sweep's first point
            points_ego = points_ego[obstacle]
            self._obstacles[sensor] = [points_ego[a:b] for a, b in zip(kept_before[:-1], kept_before[1:])]
        return self._obstacles[sensor]

    def hidden(self, points_ecef: np.ndarray, viewpoint_ecef: np.ndarray, timestamp_ns: int, margin_m: float) -> np.ndarray:
        """Which points lie in the shadow of the radar at ``viewpoint_ecef`` at ``timestamp_ns``.

        Parameters
        ----------
        points_ecef : numpy.ndarray
            ``[N, 3]`` float64 ECEF metres.
        viewpoint_ecef : numpy.ndarray
            ``[3]`` float64 ECEF metres, the radar.
        timestamp_ns : int
            When the points were seen: every lidar's sweep nearest it (within :data:`MAX_SWEEP_GAP_NS`)
            gives the obstacles, all moved into the ego frame of this time, whose ground plane the
            test works in.
        margin_m : float
            How far beyond the nearest obstacle a point must lie.

        Returns
        -------
        numpy.ndarray
            ``[N]`` bool; all False without a sweep near ``timestamp_ns``.
        """
        points_ecef = np.asarray(points_ecef, np.float64).reshape(-1, 3)
        if points_ecef.shape[0] == 0:
            return np.zeros(0, bool)
        ego_T_ecef = self._pose(int(timestamp_ns)).inverse()
        obstacles = [np.zeros((0, 3))]
        for sensor in self.sensors:
            stamps = self.timestamps[sensor]
            if stamps.size == 0:
                continue
            k = int(np.argmin(np.abs(stamps - np.int64(timestamp_ns))))
            if abs(int(stamps[k]) - int(timestamp_ns)) <= MAX_SWEEP_GAP_NS:
                sweep_ego = self.sweep_obstacles(sensor)[k]
                obstacles.append(ego_T_ecef.compose(self._pose(int(stamps[k]))).transform_points(sweep_ego))
        obstacles_ego = np.concatenate(obstacles)
        if obstacles_ego.shape[0] == 0:
            return np.zeros(points_ecef.shape[0], bool)
        return hidden_behind_obstacles(
            ego_T_ecef.transform_points(points_ecef)[:, :2],
            ego_T_ecef.transform_points(np.asarray(viewpoint_ecef, np.float64).reshape(1, 3))[0, :2],
            obstacles_ego[:, :2], margin_m=margin_m, bin_rad=SHADOW_BIN_RAD,
        )
