"""Where range-Doppler cells lie: DOA per cell, points in the ego frame, and the Doppler test's residual."""

from __future__ import annotations

import numpy as np

from zendar_dataset.geometry.frames import EgoPoses, ego_T_sensor
from zendar_dataset.radar import FmcwParams, detections_to_points, estimate_azimuth, is_centro_symmetric
from zendar_dataset.radar.cfar import cell_spacing

VELOCITY_HALF_STEP_NS = 50_000_000  # central difference over +-50 ms of tracklog


def mount_velocity_ego(poses: EgoPoses, point_ego: np.ndarray, timestamp_ns: int) -> np.ndarray:
    """Velocity over ground [3] (m/s, ego axes at ``timestamp_ns``) of a point fixed to the car.

    A central difference of interpolated poses, so it includes the yaw rate's
    contribution at the radar's mounting point.
    """
    start, end = poses.tracklog.span_ns
    t0 = max(start, timestamp_ns - VELOCITY_HALF_STEP_NS)
    t1 = min(end, timestamp_ns + VELOCITY_HALF_STEP_NS)
    displacement_ecef = poses.ego_to_ecef(point_ego, t1) - poses.ego_to_ecef(point_ego, t0)
    velocity_ecef = displacement_ecef / ((t1 - t0) * 1e-9)
    return poses.ecef_T_ego(timestamp_ns).inverse().rotate_vectors(velocity_ecef)


def locate_cells(
    cube: np.ndarray, range_bin: np.ndarray, doppler_bin: np.ndarray, timestamp_ns: int, calibration, poses: EgoPoses
) -> tuple[np.ndarray, np.ndarray]:
    """Where range-Doppler cells of one cube ``[R, D, A]`` lie, and their Doppler-test residual.

    Parameters
    ----------
    cube : numpy.ndarray
        ``[R, D, A]`` complex range-Doppler cube.
    range_bin, doppler_bin : numpy.ndarray
        ``[N]`` int cell indices (Doppler bin ``D // 2`` is zero velocity), e.g. CFAR peaks or the
        cells of a predicted mask.
    timestamp_ns : int
        The cube's timestamp.
    calibration
        The radar's calibration record (``format.RadarCalibration``).
    poses : EgoPoses
        The scene's ego poses.

    Returns
    -------
    points_ego : numpy.ndarray
        ``[N, 3]`` float64 metres, ego frame at ``timestamp_ns`` (Bartlett DOA of each cell's antenna
        vector, on the radar's plane).
    residual_mps : numpy.ndarray
        ``[N]`` float64 measured radial velocity minus a static point's at that azimuth (m/s, wrapped
        onto the unambiguous Doppler span).
    """
    params = FmcwParams.from_calibration(calibration, n_samples=cube.shape[0], n_chirps=cube.shape[1])
    range_bin_m, doppler_bin_mps = cell_spacing(params, cube.shape[0], cube.shape[1])
    range_bin = np.asarray(range_bin, np.int64)
    doppler_bin = np.asarray(doppler_bin, np.int64)
    range_m = range_bin * float(range_bin_m)
    velocity_mps = (doppler_bin - cube.shape[1] // 2) * float(doppler_bin_mps)
    snapshots = cube[range_bin, doppler_bin]  # [N, A]
    # Forward-backward averaging where the array allows it: an imported radar's need not be symmetric.
    azimuth_rad = estimate_azimuth(snapshots, params.rx_positions_m, params.wavelength_m,
                                   forward_backward=is_centro_symmetric(params.rx_positions_m))
    ego_T_radar = ego_T_sensor(calibration)
    points_ego = detections_to_points(range_m, azimuth_rad, ego_T_radar)

    # A static point's range changes at -(line of sight . radar velocity).
    radar_velocity_ego = mount_velocity_ego(poses, ego_T_radar.translation, timestamp_ns)
    line_of_sight_radar = np.stack([np.cos(azimuth_rad), np.sin(azimuth_rad), np.zeros_like(azimuth_rad)], axis=1)
    static_mps = -ego_T_radar.rotate_vectors(line_of_sight_radar) @ radar_velocity_ego
    # Doppler is ambiguous modulo D bins: compare velocities on that circle.
    span_mps = cube.shape[1] * params.doppler_bin_mps
    residual_mps = (velocity_mps - static_mps + span_mps / 2) % span_mps - span_mps / 2
    return points_ego, residual_mps
