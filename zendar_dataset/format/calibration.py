"""Sensor calibration records of format v1 (the ``calibration`` attribute).

Plain arrays only: geometry (composing poses, projecting points) lives in
``zendar_dataset.geometry``.  Each record is the pose of a sensor in the ego
frame, ``p_ego = R(rotation_wxyz) · p_sensor + translation_m``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from zendar_dataset._arrays import float64_array_or_none
from zendar_dataset.errors import ZendarFormatError

_QUATERNION_NORM_TOLERANCE = 1e-6


def _array(value: Any, shape: tuple[int, ...], name: str, problems: list[str]) -> np.ndarray:
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        problems.append(f"{name}: expected numbers of shape {list(shape)}, found {value!r}")
        return np.zeros(shape)
    if array.shape != shape:
        problems.append(f"{name}: expected shape {list(shape)}, found {list(array.shape)}")
        return np.zeros(shape)
    if not np.all(np.isfinite(array)):
        problems.append(f"{name}: expected finite numbers, found {array.tolist()}")
    return array


@dataclass
class SensorCalibration:
    """Pose of a sensor in the ego frame.

    Attributes
    ----------
    rotation_wxyz : ndarray, shape (4,), float64
        Unit quaternion (scalar first) rotating sensor-frame vectors into the ego frame.
    translation_m : ndarray, shape (3,), float64
        Sensor origin in the ego frame, metres.
    """

    rotation_wxyz: np.ndarray
    translation_m: np.ndarray

    def __post_init__(self) -> None:
        problems = self._check()
        if problems:
            raise ZendarFormatError("; ".join(problems), problems)

    def _check(self, name: str = "sensor") -> list[str]:
        problems: list[str] = []
        self.rotation_wxyz = _array(self.rotation_wxyz, (4,), f"{name}.rotation_wxyz", problems)
        self.translation_m = _array(self.translation_m, (3,), f"{name}.translation_m", problems)
        norm = float(np.linalg.norm(self.rotation_wxyz))
        if not problems and abs(norm - 1.0) > _QUATERNION_NORM_TOLERANCE:
            problems.append(f"{name}.rotation_wxyz: expected a unit quaternion, found norm {norm:.9f}")
        return problems

    def to_json(self) -> dict[str, Any]:
        """JSON-ready dict with the format's key names."""
        out: dict[str, Any] = {}
        for field in fields(self):
            value = getattr(self, field.name)
            out[field.name] = value.tolist() if isinstance(value, np.ndarray) else value
        return out


@dataclass
class RadarCalibration(SensorCalibration):
    """A radar: pose plus the bin spacing needed to read its cubes.

    Attributes
    ----------
    center_frequency_hz, bandwidth_hz : float
        Carrier frequency and chirp bandwidth, Hz.
    range_bin_m : float
        Range bin r is at ``r * range_bin_m`` metres.
    doppler_bin_mps : float
        Doppler bin d is at ``(d - D/2) * doppler_bin_mps`` m/s; positive means the range grows.
    rx_positions_m : ndarray, shape (A, 3), float64
        Receive antenna positions in the radar frame, metres.
    fov_azimuth_deg : float or None
        Optional: full horizontal field of view, degrees, centred on the boresight (0 < fov <= 360).
    sar_bandwidth_hz : float or None
        Optional: swept bandwidth of the waveform this radar's SAR images are formed from, Hz (SAR
        range resolution ``c / (2 sar_bandwidth_hz)``); absent when it is ``bandwidth_hz``.
    sar_azimuth_window : str or None
        Optional: the slow-time taper this radar's SAR images were formed with (``"rectangular"``,
        ``"hann"``: :data:`zendar_dataset.sar.aperture.AZIMUTH_WINDOWS`); it sets their cross-range
        resolution. Absent: not recorded.
    """

    center_frequency_hz: float
    bandwidth_hz: float
    range_bin_m: float
    doppler_bin_mps: float
    rx_positions_m: np.ndarray
    fov_azimuth_deg: float | None = None
    sar_bandwidth_hz: float | None = None
    sar_azimuth_window: str | None = None

    def _check(self, name: str = "radar") -> list[str]:
        problems = super()._check(name)
        for key in ("center_frequency_hz", "bandwidth_hz", "range_bin_m", "doppler_bin_mps"):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)) or not value > 0:
                problems.append(f"{name}.{key}: expected a positive number, found {value!r}")
            else:
                setattr(self, key, float(value))
        positions = float64_array_or_none(self.rx_positions_m)
        if positions is None or positions.ndim != 2 or positions.shape[1] != 3 or positions.shape[0] < 1:
            shape = None if positions is None else list(positions.shape)
            problems.append(f"{name}.rx_positions_m: expected shape [A, 3] with A >= 1, found {shape}")
        else:
            self.rx_positions_m = positions
        fov = self.fov_azimuth_deg
        if fov is not None:
            if isinstance(fov, bool) or not isinstance(fov, (int, float, np.floating, np.integer)) or not 0 < fov <= 360:
                problems.append(f"{name}.fov_azimuth_deg: expected a number in (0, 360], found {fov!r}")
            else:
                self.fov_azimuth_deg = float(fov)
        sar_bandwidth = self.sar_bandwidth_hz
        if sar_bandwidth is not None:
            if (isinstance(sar_bandwidth, bool) or not isinstance(sar_bandwidth, (int, float, np.floating, np.integer))
                    or not (math.isfinite(sar_bandwidth) and sar_bandwidth > 0)):
                problems.append(f"{name}.sar_bandwidth_hz: expected a positive number, found {sar_bandwidth!r}")
            else:
                self.sar_bandwidth_hz = float(sar_bandwidth)
        window = self.sar_azimuth_window
        if window is not None and not (isinstance(window, str) and window):
            problems.append(f"{name}.sar_azimuth_window: expected a window name (a non-empty string), found {window!r}")
        return problems

    def to_json(self) -> dict[str, Any]:
        out = super().to_json()
        for key in ("fov_azimuth_deg", "sar_bandwidth_hz", "sar_azimuth_window"):
            if out.get(key) is None:
                out.pop(key, None)
        return out


@dataclass
class CameraCalibration(SensorCalibration):
    """A camera: pose plus pinhole intrinsics.

    Attributes
    ----------
    K : ndarray, shape (3, 3), float64
        Intrinsic matrix, pixels.
    distortion : ndarray, shape (5,), float64
        Distortion coefficients (k1, k2, p1, p2, k3).
    width, height : int
        Image size, pixels.
    """

    K: np.ndarray
    distortion: np.ndarray
    width: int
    height: int

    def _check(self, name: str = "camera") -> list[str]:
        problems = super()._check(name)
        self.K = _array(self.K, (3, 3), f"{name}.K", problems)
        self.distortion = _array(self.distortion, (5,), f"{name}.distortion", problems)
        for key in ("width", "height"):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value <= 0:
                problems.append(f"{name}.{key}: expected a positive integer, found {value!r}")
            else:
                setattr(self, key, int(value))
        return problems


_RADAR_KEYS = {f.name for f in fields(RadarCalibration)}
_CAMERA_KEYS = {f.name for f in fields(CameraCalibration)}
_SENSOR_KEYS = {f.name for f in fields(SensorCalibration)}
_OPTIONAL_KEYS = {"fov_azimuth_deg", "sar_bandwidth_hz", "sar_azimuth_window"}


def _sensor_from_json(name: str, entry: Any, problems: list[str]) -> SensorCalibration | None:
    if not isinstance(entry, dict):
        problems.append(f"sensors.{name}: expected an object, found {type(entry).__name__}")
        return None
    if "center_frequency_hz" in entry or "rx_positions_m" in entry:
        cls, keys = RadarCalibration, _RADAR_KEYS
    elif "K" in entry:
        cls, keys = CameraCalibration, _CAMERA_KEYS
    else:
        cls, keys = SensorCalibration, _SENSOR_KEYS
    missing = sorted(keys - _OPTIONAL_KEYS - entry.keys())
    if missing:
        problems.append(f"sensors.{name}: missing {', '.join(missing)}")
        return None
    record = object.__new__(cls)
    for key in keys:
        setattr(record, key, entry.get(key))
    found = record._check(f"sensors.{name}")
    if found:
        problems.extend(found)
        return None
    return record


@dataclass
class Calibration:
    """Every sensor's calibration, keyed by sensor name (``"imu"`` is the tracklog's IMU)."""

    sensors: dict[str, SensorCalibration]

    @classmethod
    def from_json(cls, value: dict | str) -> "Calibration":
        """Parse the ``calibration`` attribute (a dict, or its JSON text).

        Raises
        ------
        ZendarFormatError
            Listing every missing key and malformed value.
        """
        if isinstance(value, (str, bytes)):
            try:
                value = json.loads(value)
            except json.JSONDecodeError as exc:
                raise ZendarFormatError(f"calibration: expected JSON, found invalid text ({exc})") from None
        if not isinstance(value, dict) or not isinstance(value.get("sensors"), dict):
            raise ZendarFormatError('calibration: expected an object {"sensors": {name: {...}}}')
        problems: list[str] = []
        sensors = {}
        for name, entry in value["sensors"].items():
            record = _sensor_from_json(name, entry, problems)
            if record is not None:
                sensors[name] = record
        if problems:
            raise ZendarFormatError("calibration: " + "; ".join(problems), [f"calibration: {p}" for p in problems])
        return cls(sensors)

    def to_json(self) -> dict[str, Any]:
        """The ``calibration`` attribute as a JSON-ready dict."""
        return {"sensors": {name: sensor.to_json() for name, sensor in self.sensors.items()}}

    def radar(self, name: str) -> RadarCalibration:
        """The calibration of radar ``name`` (ZendarFormatError when absent or not a radar)."""
        return self._typed(name, RadarCalibration, "radar")

    def camera(self, name: str) -> CameraCalibration:
        """The calibration of camera ``name`` (ZendarFormatError when absent or not a camera)."""
        return self._typed(name, CameraCalibration, "camera")

    def _typed(self, name: str, cls: type, kind: str):
        sensor = self.sensors.get(name)
        if not isinstance(sensor, cls):
            found = "nothing" if sensor is None else type(sensor).__name__
            raise ZendarFormatError(f"calibration: expected {kind} calibration for sensor {name!r}, found {found}")
        return sensor
