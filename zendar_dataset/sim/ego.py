"""The ego vehicle: sensor mounts, true motion and the GPS/IMU tracklog.

The true ego pose comes from the ego's :class:`~zendar_dataset.sim.trajectory.Trajectory`
(flat ground, no roll or pitch).  The tracklog samples the IMU pose at 100 Hz
and converts it to ECEF through pyproj (``LocalENU``).  The *written* tracklog
carries GPS/IMU-grade error: a slowly wandering bias (first-order Gauss-Markov,
a few centimetres and a few hundredths of a degree, correlation time tens of
seconds, as an INS blending GNSS) plus a small white jitter.  Over a SAR
aperture (~0.1-1 s) the bias is nearly constant, so images stay focused but are
slightly misplaced, while the jitter costs some focus, as the paper notes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from zendar_dataset.geometry.geodesy import LocalENU
from zendar_dataset.geometry.quaternion import matrix_to_quat_wxyz
from zendar_dataset.geometry.se3 import SE3
from zendar_dataset.radar.fmcw import FmcwParams
from zendar_dataset.sim.profiles import SimProfile
from zendar_dataset.sim.radar_model import RadarFrontEnd
from zendar_dataset.sim.rotate import compose, rotate
from zendar_dataset.sim.sar_formation import AZIMUTH_WINDOW
from zendar_dataset.sim.trajectory import Trajectory

TRACKLOG_RATE_HZ = 100.0
RADARS = ("front_left", "front_right")
LIDAR = "top"
CAMERA = "front"
IMU = "imu"


def _yaw_matrix(yaw_rad: float) -> np.ndarray:
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


# Each corner radar's horizontal field of view (full width, centred on its boresight): twice the
# one-way 3 dB half-beamwidth of the modelled antenna (RadarFrontEnd, 60 deg), as data sheets of
# corner radars quote it (e.g. +-60 deg at -3 dB).  Recorded in the calibration as fov_azimuth_deg.
RADAR_FOV_AZIMUTH_DEG = 2.0 * RadarFrontEnd().half_beam_azimuth_deg

# The ego's body: a mid-size car (length, width, height, metres); the ego frame's origin is on the
# ground under the midpoint of its front bumper, so the body's centre is at x = -length / 2.
EGO_SIZE_M = np.array([4.7, 1.9, 1.5])

# Sensor poses in the ego frame (x forward, y left, z up; origin under the front bumper).
EGO_T_SENSOR: dict[str, SE3] = {
    "front_left": SE3(_yaw_matrix(np.radians(45.0)), [-0.3, 0.85, 0.5]),
    "front_right": SE3(_yaw_matrix(np.radians(-45.0)), [-0.3, -0.85, 0.5]),
    LIDAR: SE3(np.eye(3), [-1.8, 0.0, 1.9]),
    # Camera optical frame: x right, y down, z forward (the frame K projects from).
    CAMERA: SE3(np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]), [-1.2, 0.0, 1.4]),
    # IMU: forward, right, down.
    IMU: SE3(np.diag([1.0, -1.0, -1.0]), [-1.5, 0.0, 0.4]),
}


@dataclass(frozen=True)
class TracklogNoise:
    """GPS/IMU error model of the written tracklog.

    Attributes
    ----------
    position_bias_m, attitude_bias_deg : float
        Standard deviation of the Gauss-Markov bias per axis.
    correlation_s : float
        Correlation time of the bias.
    position_jitter_m, attitude_jitter_deg : float
        Standard deviation of the white jitter per sample.
    """

    position_bias_m: float = 0.03
    attitude_bias_deg: float = 0.05
    correlation_s: float = 30.0
    position_jitter_m: float = 0.0002
    attitude_jitter_deg: float = 0.002


def radar_params(profile: SimProfile) -> FmcwParams:
    """The FMCW waveform of the profile (4-receiver ULA at half-wavelength spacing along y)."""
    wavelength = 299_792_458.0 / profile.center_frequency_hz
    rx = np.zeros((profile.n_rx, 3))
    rx[:, 1] = (np.arange(profile.n_rx) - (profile.n_rx - 1) / 2) * wavelength / 2
    return FmcwParams(
        center_frequency_hz=profile.center_frequency_hz,
        bandwidth_hz=profile.bandwidth_hz,
        sample_rate_hz=profile.sample_rate_hz,
        n_samples=profile.n_range_bins,
        n_chirps=profile.n_doppler_bins,
        chirp_interval_s=profile.chirp_interval_s,
        rx_positions_m=rx,
    )


def camera_intrinsics(profile: SimProfile) -> tuple[np.ndarray, np.ndarray]:
    """``K`` [3, 3] (70 deg horizontal field of view) and mild barrel distortion (k1, k2, p1, p2, k3)."""
    height, width = profile.camera_shape
    focal = (width / 2) / np.tan(np.radians(35.0))
    k = np.array([[focal, 0.0, (width - 1) / 2], [0.0, focal, (height - 1) / 2], [0.0, 0.0, 1.0]])
    return k, np.array([-0.05, 0.01, 0.0005, -0.0003, 0.0])


def calibration(profile: SimProfile) -> dict:
    """The scene calibration (format v1 ``calibration`` attribute) for the profile."""
    params = radar_params(profile)
    sensors: dict[str, dict] = {}
    for name, pose in EGO_T_SENSOR.items():
        entry = {"rotation_wxyz": pose.as_wxyz().tolist(), "translation_m": pose.translation.tolist()}
        if name in RADARS:
            entry.update(
                center_frequency_hz=params.center_frequency_hz,
                bandwidth_hz=params.bandwidth_hz,
                range_bin_m=params.range_bin_m,
                doppler_bin_mps=params.doppler_bin_mps,
                rx_positions_m=params.rx_positions_m.tolist(),
                sample_rate_hz=params.sample_rate_hz,
                n_samples=params.n_samples,
                n_chirps=params.n_chirps,
                chirp_interval_s=params.chirp_interval_s,
                range_window="hann",
                doppler_window="hann",
                fov_azimuth_deg=RADAR_FOV_AZIMUTH_DEG,
                sar_bandwidth_hz=profile.sar_bandwidth_hz,
                sar_azimuth_window=AZIMUTH_WINDOW,
            )
        elif name == CAMERA:
            k, distortion = camera_intrinsics(profile)
            entry.update(K=k.tolist(), distortion=distortion.tolist(),
                         width=int(profile.camera_shape[1]), height=int(profile.camera_shape[0]))
        sensors[name] = entry
    return {"sensors": sensors}


def enu_T_ego(trajectory: Trajectory, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """True ego rotations ``[..., 3, 3]`` and translations ``[..., 3]`` (ego -> ENU) at times ``[...]``."""
    yaw = trajectory.yaw_at(t_s)
    c, s = np.cos(yaw), np.sin(yaw)
    zero, one = np.zeros_like(yaw), np.ones_like(yaw)
    rotation = np.stack([np.stack([c, -s, zero], -1), np.stack([s, c, zero], -1), np.stack([zero, zero, one], -1)], -2)
    return rotation, trajectory.position_at(t_s)


def ego_boxes(trajectory: Trajectory, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The ego's body at times ``[T]``: centres ``[T, 3]`` (ENU, z at half height), size ``[3]``, yaws ``[T]``."""
    yaw = trajectory.yaw_at(t_s)
    center = trajectory.position_at(t_s).copy()
    center[..., 0] -= EGO_SIZE_M[0] / 2 * np.cos(yaw)
    center[..., 1] -= EGO_SIZE_M[0] / 2 * np.sin(yaw)
    center[..., 2] = EGO_SIZE_M[2] / 2
    return center, EGO_SIZE_M, yaw


def sensor_poses_enu(trajectory: Trajectory, sensor: str, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """True ``enu_T_sensor``: rotations ``[..., 3, 3]`` and positions ``[..., 3]``."""
    rotation, translation = enu_T_ego(trajectory, t_s)
    mount = EGO_T_SENSOR[sensor]
    return compose(rotation, mount.rotation), translation + rotate(rotation, mount.translation)


def _gauss_markov(rng: np.random.Generator, n: int, dims: int, sigma: float, correlation_s: float, dt: float) -> np.ndarray:
    phi = np.exp(-dt / correlation_s)
    drive = rng.standard_normal((n, dims)) * sigma * np.sqrt(1 - phi**2)
    out = np.empty((n, dims))
    out[0] = rng.standard_normal(dims) * sigma
    for i in range(1, n):
        out[i] = phi * out[i - 1] + drive[i]
    return out


@dataclass(frozen=True)
class Tracklog:
    """IMU poses in ECEF: ``timestamp_ns`` [K], ``position_ecef`` [K, 3], ``attitude_wxyz`` [K, 4]."""

    timestamp_ns: np.ndarray
    position_ecef: np.ndarray
    attitude_wxyz: np.ndarray


def make_tracklogs(
    trajectory: Trajectory,
    enu: LocalENU,
    start_ns: int,
    t_start_s: float,
    t_end_s: float,
    rng: np.random.Generator,
    noise: TracklogNoise = TracklogNoise(),
) -> tuple[Tracklog, Tracklog]:
    """The true and the noisy (written) tracklog between ``t_start_s`` and ``t_end_s``.

    Times are scene seconds; ``timestamp_ns = start_ns + round(t * 1e9)``.
    """
    t = np.arange(np.ceil(t_start_s * TRACKLOG_RATE_HZ), np.floor(t_end_s * TRACKLOG_RATE_HZ) + 1) / TRACKLOG_RATE_HZ
    rotation, position = sensor_poses_enu(trajectory, IMU, t)
    ecef_r_enu = enu.ecef_R_enu
    truth = Tracklog(
        start_ns + np.rint(t * 1e9).astype(np.int64),
        enu.enu_to_ecef(position),
        matrix_to_quat_wxyz(compose(ecef_r_enu, rotation)),
    )
    dt = 1.0 / TRACKLOG_RATE_HZ
    n = t.shape[0]
    position_error = _gauss_markov(rng, n, 3, noise.position_bias_m, noise.correlation_s, dt)
    position_error += rng.standard_normal((n, 3)) * noise.position_jitter_m
    angle_error = _gauss_markov(rng, n, 3, np.radians(noise.attitude_bias_deg), noise.correlation_s, dt)
    angle_error += rng.standard_normal((n, 3)) * np.radians(noise.attitude_jitter_deg)
    perturb = Rotation.from_rotvec(angle_error).as_matrix()
    noisy = Tracklog(
        truth.timestamp_ns,
        enu.enu_to_ecef(position + position_error),
        matrix_to_quat_wxyz(compose(compose(ecef_r_enu, perturb), rotation)),
    )
    return truth, noisy
