"""Planar trajectories (ego and cars): a path followed with a speed profile.

A path is integrated from a curvature profile ``kappa(s)`` along its arc length;
a speed profile (cruise, brake to a stop, wait, accelerate) gives ``s(t)``.
Both are sampled every millisecond, which keeps linear interpolation of the
position within ~1e-6 m of the smooth curve (well under the 3.9 mm wavelength).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING

import numba
import numpy as np

if TYPE_CHECKING:  # world.py builds on Trajectory, so the import would be circular at run time
    from zendar_dataset.sim.world import Road

SAMPLE_INTERVAL_S = 1e-3


@dataclass(frozen=True)
class Trajectory:
    """Ground-plane motion of a rigid body in the scene's ENU frame.

    Attributes
    ----------
    time_s : numpy.ndarray
        ``[T]`` float64 seconds from the scene start, uniform.
    position_enu : numpy.ndarray
        ``[T, 3]`` float64 metres (reference point of the body, on the ground).
    yaw_rad : numpy.ndarray
        ``[T]`` float64 heading (x axis of the body) counter-clockwise from east.
    speed_mps : numpy.ndarray
        ``[T]`` float64 speed along the heading.
    """

    time_s: np.ndarray
    position_enu: np.ndarray
    yaw_rad: np.ndarray
    speed_mps: np.ndarray

    def __post_init__(self) -> None:
        n = self.time_s.shape[0]
        if self.position_enu.shape != (n, 3) or self.yaw_rad.shape != (n,) or self.speed_mps.shape != (n,):
            raise ValueError("trajectory arrays must be [T], [T, 3], [T], [T]")

    def _interp(self, values: np.ndarray, t_s: np.ndarray) -> np.ndarray:
        t = np.asarray(t_s, dtype=np.float64)
        pos = np.clip((t - self.time_s[0]) / (self.time_s[1] - self.time_s[0]), 0.0, self.time_s.shape[0] - 1.000001)
        lower = pos.astype(np.int64)
        frac = pos - lower
        if values.ndim == 2:
            frac = frac[..., None]
        return values[lower] * (1.0 - frac) + values[lower + 1] * frac

    def position_at(self, t_s: np.ndarray) -> np.ndarray:
        """``[..., 3]`` ENU position at times ``[...]`` (held constant outside the span)."""
        return self._interp(self.position_enu, t_s)

    @cached_property
    def _yaw_unwrapped(self) -> np.ndarray:
        # Unwrapped once: every sensor frame asks every car's yaw, often many times.
        return np.unwrap(self.yaw_rad)

    @cached_property
    def _yaw_rate(self) -> np.ndarray:
        return np.gradient(self._yaw_unwrapped, self.time_s)

    def yaw_at(self, t_s: np.ndarray) -> np.ndarray:
        return self._interp(self._yaw_unwrapped, t_s)

    def velocity_at(self, t_s: np.ndarray) -> np.ndarray:
        """``[..., 3]`` ENU velocity (m/s)."""
        yaw = self.yaw_at(t_s)
        speed = self._interp(self.speed_mps, t_s)
        return np.stack([speed * np.cos(yaw), speed * np.sin(yaw), np.zeros_like(speed)], axis=-1)

    def yaw_rate_at(self, t_s: np.ndarray) -> np.ndarray:
        return self._interp(self._yaw_rate, t_s)


def speed_profile(
    duration_s: float,
    cruise_mps: float,
    stops: list[tuple[float, float]],
    *,
    start_mps: float | None = None,
    accel_mps2: float = 2.5,
) -> tuple[np.ndarray, np.ndarray]:
    """Speed over time: cruise, with full stops ``(stop_time_s, wait_s)``.

    The speed follows the target with a bounded acceleration (``accel_mps2``),
    so stops are approached by braking and left by accelerating.

    Returns
    -------
    time_s, speed_mps : numpy.ndarray
        ``[T]`` float64 each, sampled every :data:`SAMPLE_INTERVAL_S`.
    """
    time_s = np.arange(0.0, duration_s + 2 * SAMPLE_INTERVAL_S, SAMPLE_INTERVAL_S)
    target = np.full(time_s.shape, float(cruise_mps))
    for stop_s, wait_s in stops:
        target[(time_s >= stop_s) & (time_s < stop_s + wait_s)] = 0.0
    current = float(cruise_mps if start_mps is None else start_mps)
    step = accel_mps2 * SAMPLE_INTERVAL_S
    # Braking must start early enough to reach zero at the stop time.
    for stop_s, _wait in stops:
        braking_s = cruise_mps / accel_mps2
        window = (time_s >= stop_s - braking_s) & (time_s < stop_s)
        target[window] = np.minimum(target[window], (stop_s - time_s[window]) * accel_mps2)
    return time_s, _follow_target(target, current, step)


@numba.njit(cache=True)
def _follow_target(target: np.ndarray, current: float, step: float) -> np.ndarray:  # pragma: no cover - compiled
    """Speeds that follow ``target`` changing by at most ``step`` per sample (a sequential recursion)."""
    speed = np.empty_like(target)
    for i in range(target.shape[0]):
        goal = target[i]
        current = min(goal, current + step) if goal > current else max(goal, current - step)
        speed[i] = current
    return speed


def travelled_distance_m(time_s: np.ndarray, speed_mps: np.ndarray) -> np.ndarray:
    """``[T]`` float64 arc length covered since ``time_s[0]`` (trapezoidal rule on a uniform grid)."""
    dt = time_s[1] - time_s[0]
    return np.concatenate([[0.0], np.cumsum(0.5 * (speed_mps[1:] + speed_mps[:-1]) * dt)])


def follow_road(
    road: Road,
    time_s: np.ndarray,
    speed_mps: np.ndarray,
    start_s_m: float,
    *,
    lateral_m: float = 0.0,
    against_road: bool = False,
) -> Trajectory:
    """Drive along the road's reference line at a fixed left offset.

    Parameters
    ----------
    road : Road
        The road whose arc length ``s`` the body follows.
    time_s, speed_mps : numpy.ndarray
        ``[T]`` float64 uniform times and speeds, as from :func:`speed_profile`.
    start_s_m : float
        Arc length at ``time_s[0]``, metres.
    lateral_m : float
        Offset to the left of the reference line, metres (one lane width for the oncoming lane).
    against_road : bool
        Drive towards decreasing ``s`` (heading turned by pi).
    """
    direction = -1.0 if against_road else 1.0
    position, yaw = road.point(start_s_m + direction * travelled_distance_m(time_s, speed_mps), lateral_m)
    if against_road:
        yaw = yaw + np.pi
    return Trajectory(time_s, position, yaw, speed_mps)


def follow_path(
    time_s: np.ndarray,
    speed_mps: np.ndarray,
    start_enu: np.ndarray,
    start_yaw_rad: float,
    curvature_at: callable,
) -> Trajectory:
    """Integrate a path with curvature ``curvature_at(s)`` (1/m) travelled at ``speed_mps``."""
    distance = travelled_distance_m(time_s, speed_mps)
    kappa = curvature_at(distance)
    yaw = start_yaw_rad + np.concatenate([[0.0], np.cumsum(0.5 * (kappa[1:] + kappa[:-1]) * np.diff(distance))])
    step = np.diff(distance)
    mid_yaw = 0.5 * (yaw[1:] + yaw[:-1])
    east = start_enu[0] + np.concatenate([[0.0], np.cumsum(step * np.cos(mid_yaw))])
    north = start_enu[1] + np.concatenate([[0.0], np.cumsum(step * np.sin(mid_yaw))])
    position = np.stack([east, north, np.full_like(east, start_enu[2])], axis=1)
    return Trajectory(time_s, position, yaw, np.asarray(speed_mps, dtype=np.float64))
