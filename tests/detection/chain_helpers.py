"""Hand-made scenes for the detection chain's tests: a parked ego, simulated point targets, SAR images.

The ego stands still at an ENU origin with the IMU's axes along ECEF's, so that
``ego_to_ecef(p) = origin_ecef + p``: every position below is easy to compute by hand.
"""

from __future__ import annotations

import numpy as np

from zendar_dataset.geometry.frames import EgoPoses
from zendar_dataset.geometry.geodesy import LocalENU
from zendar_dataset.geometry.poses import PoseInterpolator
from zendar_dataset.geometry.se3 import SE3
from zendar_dataset.radar.fmcw import SPEED_OF_LIGHT_MPS, FmcwParams, beat_signal_exact
from zendar_dataset.radar.range_doppler import range_doppler
from zendar_dataset.sar.frames import SarFrames

T0_NS = 1_300_000_000_000_000_000


def parked_poses() -> EgoPoses:
    """Ego poses of a car standing still for 10 s from :data:`T0_NS`; ego axes = ECEF axes."""
    return driving_poses(0.0, 0.0)


def driving_poses(speed_mps: float, yaw_rate_rad_s: float) -> EgoPoses:
    """Ego poses of a car that starts at :data:`T0_NS` with its axes along ECEF's and, over 10 s,
    moves along ECEF x at ``speed_mps`` while turning about ECEF z at ``yaw_rate_rad_s`` (Slerp
    between the two samples turns at a constant rate when the turn stays below 180 deg)."""
    enu = LocalENU(48.0, 11.0, 500.0)
    stamps = np.array([T0_NS, T0_NS + 10_000_000_000], np.int64)
    half_turn = 10.0 * yaw_rate_rad_s / 2
    positions = np.stack([enu.origin_ecef, enu.origin_ecef + [10.0 * speed_mps, 0.0, 0.0]])
    attitudes = np.array([[1.0, 0, 0, 0], [np.cos(half_turn), 0, 0, np.sin(half_turn)]])
    return EgoPoses(PoseInterpolator(stamps, positions, attitudes), SE3.identity(), enu)


def radar_params(n_samples: int = 64, n_chirps: int = 32) -> FmcwParams:
    """A 77 GHz radar, 0.1875 m range bins, 4 receivers half a wavelength apart along y.

    The sweep fills the chirp interval, as :meth:`FmcwParams.from_calibration` assumes.
    """
    wavelength = SPEED_OF_LIGHT_MPS / 77e9
    rx = np.zeros((4, 3))
    rx[:, 1] = np.arange(4) * wavelength / 2
    chirp_interval_s = 20e-6
    return FmcwParams(
        center_frequency_hz=77e9, bandwidth_hz=800e6, sample_rate_hz=n_samples / chirp_interval_s, n_samples=n_samples,
        n_chirps=n_chirps, chirp_interval_s=chirp_interval_s, rx_positions_m=rx,
    )


def radar_calibration(params: FmcwParams, yaw_rad: float, translation_m) -> dict:
    """A format-v1 radar calibration entry: the waveform and the mount in the ego frame."""
    half = yaw_rad / 2
    return {**params.to_calibration(), "rotation_wxyz": [np.cos(half), 0.0, 0.0, np.sin(half)], "translation_m": list(translation_m)}


def simulate_cube(params: FmcwParams, positions_radar: np.ndarray, velocities_radar: np.ndarray, amplitudes, noise: float, seed: int = 0) -> np.ndarray:
    """``[R, D, A]`` complex64 cube of point targets (exact beat signal) plus complex Gaussian noise."""
    raw = beat_signal_exact(params, positions_radar, velocities_radar, np.asarray(amplitudes, np.complex128))
    rng = np.random.default_rng(seed)
    raw = raw + noise * (rng.standard_normal(raw.shape) + 1j * rng.standard_normal(raw.shape)) / np.sqrt(2)
    return range_doppler(raw.astype(np.complex64))


class SarReader:
    """Just what :class:`SarFrames` reads from a scene: SAR sensors, their timestamps and arrays."""

    def __init__(self, frames: dict[str, dict[str, np.ndarray]]) -> None:
        self.frames = frames

    def sensors(self, group: str) -> list[str]:
        return sorted(self.frames) if group == "sar" else []

    def timestamps(self, stream: str) -> np.ndarray:
        return self.frames[stream.split("/")[1]]["timestamp_ns"]

    def array(self, path: str) -> np.ndarray:
        _group, sensor, name = path.split("/")
        return self.frames[sensor][name]


def sar_frame(poses: EgoPoses, corner_ego_xy, pixel_m: float, shape: tuple[int, int], bright_ego_xy, bright_amplitude: float,
              seed: int = 0) -> dict[str, np.ndarray]:
    """One SAR frame at :data:`T0_NS` on the ego's ground plane: unit complex Gaussian noise
    (``E|n|² = 1``) and pixels of ``bright_amplitude`` at the points ``bright_ego_xy``.

    Rows run along ego x from ``corner_ego_xy``, columns along ego y.
    """
    rng = np.random.default_rng(seed)
    image = ((rng.standard_normal(shape) + 1j * rng.standard_normal(shape)) / np.sqrt(2)).astype(np.complex64)
    corner = np.array([corner_ego_xy[0], corner_ego_xy[1], 0.0])
    for x, y in np.reshape(bright_ego_xy, (-1, 2)):
        image[int(round((x - corner[0]) / pixel_m)), int(round((y - corner[1]) / pixel_m))] = bright_amplitude
    origin = poses.ego_to_ecef(corner[None], T0_NS)[0]
    return {
        "timestamp_ns": np.array([T0_NS], np.int64),
        "origin_ecef": origin[None],
        "di_ecef": (poses.ego_to_ecef((corner + [pixel_m, 0, 0])[None], T0_NS)[0] - origin)[None],
        "dj_ecef": (poses.ego_to_ecef((corner + [0, pixel_m, 0])[None], T0_NS)[0] - origin)[None],
        "image": image[None],
    }


def sar_frames(**frames: dict[str, np.ndarray]) -> SarFrames:
    """:class:`SarFrames` over the given per-sensor frames (:func:`sar_frame`)."""
    return SarFrames(SarReader(frames))


class LidarReader:
    """Just what :class:`~zendar_dataset.sar.shadow.RadarShadow` reads from a scene: lidar ``top``
    mounted at ``lidar_ego`` turned by ``yaw_rad`` about the ego's z, with one sweep of
    ``points_lidar`` ``[P, 3]`` (its own frame) at ``sweep_ns``, on the ego ``poses`` (default: parked)."""

    def __init__(self, points_lidar: np.ndarray, lidar_ego, yaw_rad: float = 0.0, poses: EgoPoses | None = None,
                 sweep_ns: int = T0_NS) -> None:
        self.points = np.asarray(points_lidar, np.float32)
        self.sweep_ns, self.poses = int(sweep_ns), parked_poses() if poses is None else poses
        half = yaw_rad / 2
        self.calibration = type("Calibration", (), {"sensors": {"top": {
            "rotation_wxyz": [float(np.cos(half)), 0.0, 0.0, float(np.sin(half))], "translation_m": [float(v) for v in lidar_ego]}}})()

    def sensors(self, group: str) -> list[str]:
        return ["top"] if group == "lidar" else []

    def timestamps(self, stream: str) -> np.ndarray:
        return np.array([self.sweep_ns], np.int64)

    def lidar_sweeps(self, sensor: str) -> tuple[np.ndarray, np.ndarray]:
        return self.points, np.array([0, len(self.points)], np.int64)

    def ego_poses(self) -> EgoPoses:
        return self.poses
