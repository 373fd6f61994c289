"""The ego vehicle: sensor mounts, true motion and the GPS/IMU tracklog.

The true ego pose comes from the ego's :class:`~zendar_dataset.sim.trajectory.Trajectory`
(flat ground, no roll or pitch).  The tracklog samples the IMU pose at 100 Hz
and converts it to ECEF through pyproj (``LocalENU``).  The *written* tracklog
carries the error of a GNSS/INS solution (:class:`TracklogNoise`): centimetres
of position error that wander over tens of seconds, driven through a velocity
error by the IMU's accelerometer noise, so they are smooth over a synthetic
aperture (hundredths of a millimetre from a straight line over 0.2 s); a few
hundredths of a degree of attitude error driven by the gyros' noise; and
zero-velocity updates that hold the position error while the ego stands.
SAR images formed from it focus as from the truth and are misplaced by the
position error, as on the real vehicle.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg
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
# Below this speed the ego stands still: the navigation applies zero-velocity updates, and a SAR
# frame whose aperture includes such a moment is marked ego_stopped (docs/format.md).
STANDSTILL_MPS = 0.01
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
    """Error model of the written tracklog: an RTK GNSS receiver blended with a tactical-grade IMU.

    Position error, per ENU axis: a second-order Gauss-Markov process
    ``e'' = -2 zeta omega e' - omega^2 e + w``, ``w`` the accelerometers' white noise (power
    spectral density ``N^2``, ``N`` the velocity random walk) and ``omega`` set so that ``e``
    keeps the GNSS's position accuracy ``sigma``: ``omega^3 = N^2 / (4 zeta sigma^2)``. The error
    reaches the position only through the velocity error ``e'`` (standard deviation
    ``N / sqrt(4 zeta omega)``, about 2 mm/s), so over a synthetic aperture it is nearly a straight
    line. Attitude error, per axis: a first-order Gauss-Markov process of standard deviation
    ``attitude_deg`` driven by the gyros' angle random walk. While the ego stands still
    (:data:`STANDSTILL_MPS`) zero-velocity updates hold the position error. Parameters and
    their sources: docs/simulator.md.

    Attributes
    ----------
    horizontal_position_m, vertical_position_m : float
        Standard deviation of the position error per horizontal axis and vertically.
    velocity_random_walk_mps_per_sqrt_h : float
        The accelerometers' velocity random walk ``N``.
    damping : float
        ``zeta`` of the position error's second-order process.
    attitude_deg : float
        Standard deviation of the attitude error per axis.
    angle_random_walk_deg_per_sqrt_h : float
        The gyros' angle random walk.
    zero_velocity_updates : bool
        Hold the position error while the ego stands still.
    """

    horizontal_position_m: float = 0.02
    vertical_position_m: float = 0.04
    velocity_random_walk_mps_per_sqrt_h: float = 0.07
    damping: float = 1.0 / math.sqrt(2.0)
    attitude_deg: float = 0.05
    angle_random_walk_deg_per_sqrt_h: float = 0.15
    zero_velocity_updates: bool = True


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


def stood_still(trajectory: Trajectory, t_start_s: float, t_end_s: float) -> bool:
    """Whether the body stood still (speed below :data:`STANDSTILL_MPS`) at some moment of ``[t_start_s, t_end_s]``."""
    inside = trajectory.time_s[(trajectory.time_s > t_start_s) & (trajectory.time_s < t_end_s)]
    times = np.concatenate([[t_start_s, t_end_s], inside])
    return bool(np.any(np.linalg.norm(trajectory.velocity_at(times), axis=-1) < STANDSTILL_MPS))


# Zero-velocity updates: the velocity error the smoother is told while the ego stands (m/s, 1 sigma).
ZERO_VELOCITY_NOISE_MPS = 1e-4


def _position_error(rng: np.random.Generator, standing: np.ndarray, sigma_m: np.ndarray, noise: TracklogNoise,
                    dt: float) -> np.ndarray:
    """Position error ``[n, 3]`` at the tracklog samples: the second-order Gauss-Markov process of
    :class:`TracklogNoise` from its stationary law, stepped exactly (Van Loan's matrix exponential).

    Where ``standing`` ``[n]``, zero-velocity updates tell the navigation that its velocity error is
    zero; a post-processed trajectory is smoothed forward and backward, so through the velocity error's
    correlation (seconds) they also pin it near the stop. The draw is conditioned on them exactly
    (Matheron's rule: subtract the Rauch-Tung-Striebel smoother's estimate given the draw's own
    velocity errors at those samples), which holds the position error while the ego stands.
    """
    vrw = noise.velocity_random_walk_mps_per_sqrt_h / 60.0
    zeta = noise.damping
    n = standing.shape[0]
    out = np.empty((n, 3))
    drive = rng.standard_normal((n, 3, 2))
    for axis, sigma in enumerate(sigma_m):
        omega = (vrw**2 / (4.0 * zeta * sigma**2)) ** (1.0 / 3.0)
        a = np.array([[0.0, 1.0], [-omega**2, -2.0 * zeta * omega]])
        driven = np.zeros((2, 2))
        driven[1, 1] = vrw**2
        block = scipy.linalg.expm(np.block([[-a, driven], [np.zeros((2, 2)), a.T]]) * dt)
        transition = tuple(block[2:, 2:].T.ravel().tolist())
        (s00, _), (s10, s11) = np.linalg.cholesky(block[2:, 2:].T @ block[:2, 2:]).tolist()
        t00, t01, t10, t11 = transition
        prior = (sigma**2, 0.0, vrw**2 / (4.0 * zeta * omega))
        # Scalar steps in a fixed order: no library-chosen reduction touches the written values.
        e = np.empty(n)
        v = np.empty(n)
        e[0], v[0] = math.sqrt(prior[0]) * drive[0, axis, 0], math.sqrt(prior[2]) * drive[0, axis, 1]
        for i in range(1, n):
            d0, d1 = drive[i, axis]
            e[i] = t00 * e[i - 1] + t01 * v[i - 1] + s00 * d0
            v[i] = t10 * e[i - 1] + t11 * v[i - 1] + s10 * d0 + s11 * d1
        if standing.any():
            noise_q = (s00 * s00, s00 * s10, s10 * s10 + s11 * s11)
            e -= _smoothed_position(np.where(standing, v, np.nan), transition, noise_q, prior)
        out[:, axis] = e
    return out


def _smoothed_position(velocity: np.ndarray, transition: tuple, noise_q: tuple, prior: tuple) -> np.ndarray:
    """Rauch-Tung-Striebel smoothed position ``[n]`` of the state (position, velocity) with transition
    ``(t00, t01, t10, t11)``, process noise and prior covariances ``(c00, c01, c11)``, given the
    velocity where ``velocity`` is not NaN (noise :data:`ZERO_VELOCITY_NOISE_MPS`)."""
    t00, t01, t10, t11 = transition
    r = ZERO_VELOCITY_NOISE_MPS**2
    n = velocity.shape[0]
    filtered = np.empty((n, 5))  # m0, m1, p00, p01, p11 after the update
    predicted = np.empty((n, 5))
    m0, m1, p00, p01, p11 = 0.0, 0.0, *prior
    for k in range(n):
        if k:
            m0, m1 = t00 * m0 + t01 * m1, t10 * m0 + t11 * m1
            a00, a01 = t00 * p00 + t01 * p01, t00 * p01 + t01 * p11
            a10, a11 = t10 * p00 + t11 * p01, t10 * p01 + t11 * p11
            p00 = a00 * t00 + a01 * t01 + noise_q[0]
            p01 = a00 * t10 + a01 * t11 + noise_q[1]
            p11 = a10 * t10 + a11 * t11 + noise_q[2]
        predicted[k] = m0, m1, p00, p01, p11
        if not math.isnan(velocity[k]):
            gain0, gain1 = p01 / (p11 + r), p11 / (p11 + r)
            residual = velocity[k] - m1
            m0, m1 = m0 + gain0 * residual, m1 + gain1 * residual
            p00, p01, p11 = p00 - gain0 * p01, p01 - gain0 * p11, p11 - gain1 * p11
        filtered[k] = m0, m1, p00, p01, p11
    smoothed = np.empty(n)
    s0, s1 = filtered[n - 1, 0], filtered[n - 1, 1]
    smoothed[n - 1] = s0
    for k in range(n - 2, -1, -1):
        f0, f1, p00, p01, p11 = filtered[k]
        q0, q1, r00, r01, r11 = predicted[k + 1]
        c00, c01 = p00 * t00 + p01 * t01, p00 * t10 + p01 * t11
        c10, c11 = p01 * t00 + p11 * t01, p01 * t10 + p11 * t11
        det = r00 * r11 - r01 * r01
        i00, i01, i11 = r11 / det, -r01 / det, r00 / det
        d0, d1 = s0 - q0, s1 - q1
        s0 = f0 + (c00 * i00 + c01 * i01) * d0 + (c00 * i01 + c01 * i11) * d1
        s1 = f1 + (c10 * i00 + c11 * i01) * d0 + (c10 * i01 + c11 * i11) * d1
        smoothed[k] = s0
    return smoothed


def _attitude_error(rng: np.random.Generator, n: int, sigma_rad: float, random_walk_rad_per_sqrt_s: float,
                    dt: float) -> np.ndarray:
    """Attitude error ``[n, 3]`` (rotation vector): first-order Gauss-Markov of standard deviation
    ``sigma_rad`` whose increments are the gyros' angle random walk (correlation ``2 sigma^2 / ARW^2``)."""
    phi = math.exp(-dt * random_walk_rad_per_sqrt_s**2 / (2.0 * sigma_rad**2))
    drive = rng.standard_normal((n, 3)) * sigma_rad * math.sqrt(1.0 - phi**2)
    out = np.empty((n, 3))
    out[0] = rng.standard_normal(3) * sigma_rad
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
    standing = np.linalg.norm(trajectory.velocity_at(t), axis=-1) < STANDSTILL_MPS
    if not noise.zero_velocity_updates:
        standing = np.zeros_like(standing)
    sigma = np.array([noise.horizontal_position_m, noise.horizontal_position_m, noise.vertical_position_m])
    position_error = _position_error(rng, standing, sigma, noise, dt)
    angle_error = _attitude_error(rng, t.shape[0], math.radians(noise.attitude_deg),
                                  math.radians(noise.angle_random_walk_deg_per_sqrt_h) / 60.0, dt)
    perturb = Rotation.from_rotvec(angle_error).as_matrix()
    noisy = Tracklog(
        truth.timestamp_ns,
        enu.enu_to_ecef(position + position_error),
        matrix_to_quat_wxyz(compose(compose(ecef_r_enu, perturb), rotation)),
    )
    return truth, noisy
