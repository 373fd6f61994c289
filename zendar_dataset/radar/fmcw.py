"""FMCW radar parameters and the exact per-sample beat-signal model.

The signal convention is the one in ``docs/architecture.md``: complex baseband
samples ``s[m, k, a]`` for chirp ``m`` (slow time ``m * T_c``), fast-time sample
``k`` (``t_k = k / f_s``) and receive antenna ``a``; for a point scatterer with
round-trip delay ``tau`` (transmitter at the sensor origin, receiver at
``rx_positions_m[a]``) and chirp slope ``S``::

    s[m, k, a] = A * exp(j*2*pi*(f_c*tau + S*tau*t_k - S*tau**2/2))

:func:`beat_signal_exact` evaluates this sample by sample from the true
geometry, so it is the reference (test oracle) for faster approximate models.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from zendar_dataset._arrays import float64_array_or_none
from zendar_dataset.errors import ZendarFormatError

SPEED_OF_LIGHT_MPS = 299_792_458.0

_SCALAR_KEYS = (
    "center_frequency_hz",
    "bandwidth_hz",
    "sample_rate_hz",
    "chirp_interval_s",
)
_COUNT_KEYS = ("n_samples", "n_chirps")
CALIBRATION_KEYS = ("center_frequency_hz", "bandwidth_hz", "range_bin_m", "doppler_bin_mps", "rx_positions_m")
"""The radar keys of the format's ``calibration`` attribute (docs/format.md)."""
_RANGE_BIN_TOLERANCE = 1e-3


@dataclass(frozen=True, eq=False)
class FmcwParams:
    """Waveform and array parameters of one FMCW radar.

    Parameters
    ----------
    center_frequency_hz : float
        Carrier ``f_c`` of the signal convention (the frequency whose phase
        ``f_c * tau`` each sample carries); sets the wavelength.
    bandwidth_hz : float
        Frequency swept during the ADC window of one chirp, ``B``.
    sample_rate_hz : float
        Complex (IQ) ADC sample rate ``f_s``.
    n_samples : int
        Fast-time samples per chirp ``N``; the sweep lasts ``N / f_s`` seconds.
    n_chirps : int
        Chirps per frame ``D``.
    chirp_interval_s : float
        Chirp repetition interval ``T_c`` (start to start); at least ``N / f_s``.
    rx_positions_m : numpy.ndarray
        ``[A, 3]`` float64, receive-antenna positions in the radar sensor frame
        (x boresight, y left, z up), metres. The transmitter is at the origin.

    Raises
    ------
    ZendarFormatError
        Listing every invalid value at once.
    """

    center_frequency_hz: float
    bandwidth_hz: float
    sample_rate_hz: float
    n_samples: int
    n_chirps: int
    chirp_interval_s: float
    rx_positions_m: np.ndarray

    def __post_init__(self) -> None:
        problems: list[str] = []
        for name in _SCALAR_KEYS:
            value = getattr(self, name)
            if not isinstance(value, (int, float, np.integer, np.floating)) or not np.isfinite(value) or value <= 0:
                problems.append(f"{name} must be a positive finite number, got {value!r}")
            else:
                object.__setattr__(self, name, float(value))
        for name in _COUNT_KEYS:
            value = getattr(self, name)
            if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or value < 1:
                problems.append(f"{name} must be a positive integer, got {value!r}")
            else:
                object.__setattr__(self, name, int(value))
        rx = float64_array_or_none(self.rx_positions_m)
        if rx is None or rx.ndim != 2 or rx.shape[1] != 3 or rx.shape[0] < 1 or not np.all(np.isfinite(rx)):
            shape = getattr(rx, "shape", None)
            problems.append(f"rx_positions_m must be a finite [A, 3] array of metres with A >= 1, got shape {shape}")
        else:
            rx.flags.writeable = False
            object.__setattr__(self, "rx_positions_m", rx)
        if not problems and self.chirp_interval_s < self.sweep_duration_s * (1 - 1e-9):
            problems.append(
                f"chirp_interval_s ({self.chirp_interval_s:g} s) is shorter than the sweep "
                f"n_samples / sample_rate_hz ({self.sweep_duration_s:g} s)"
            )
        if problems:
            raise ZendarFormatError("invalid FMCW parameters: " + "; ".join(problems), problems)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, FmcwParams):
            return NotImplemented
        return all(getattr(self, k) == getattr(other, k) for k in (*_SCALAR_KEYS, *_COUNT_KEYS)) and np.array_equal(
            self.rx_positions_m, other.rx_positions_m
        )

    __hash__ = None  # type: ignore[assignment]  # holds an array; equality is by value

    @property
    def sweep_duration_s(self) -> float:
        """ADC window of one chirp, ``N / f_s`` (s)."""
        return self.n_samples / self.sample_rate_hz

    @property
    def slope_hz_per_s(self) -> float:
        """Chirp slope ``S = B / (N / f_s)`` (Hz/s)."""
        return self.bandwidth_hz / self.sweep_duration_s

    @property
    def wavelength_m(self) -> float:
        """Carrier wavelength ``c / f_c`` (m)."""
        return SPEED_OF_LIGHT_MPS / self.center_frequency_hz

    @property
    def range_bin_m(self) -> float:
        """Range spacing of an ``N``-point range FFT, ``c f_s / (2 S N) = c / (2 B)`` (m)."""
        return SPEED_OF_LIGHT_MPS * self.sample_rate_hz / (2.0 * self.slope_hz_per_s * self.n_samples)

    @property
    def max_range_m(self) -> float:
        """Unambiguous range of complex sampling, ``N * range_bin_m`` (m)."""
        return self.n_samples * self.range_bin_m

    @property
    def doppler_bin_mps(self) -> float:
        """Radial-velocity spacing of a ``D``-point Doppler FFT, ``lambda / (2 D T_c)`` (m/s)."""
        return self.wavelength_m / (2.0 * self.n_chirps * self.chirp_interval_s)

    @property
    def max_velocity_mps(self) -> float:
        """Unambiguous radial speed, ``lambda / (4 T_c)``; velocities lie in ``[-max, max)`` (m/s)."""
        return self.wavelength_m / (4.0 * self.chirp_interval_s)

    @property
    def frame_duration_s(self) -> float:
        """Slow-time extent of one frame, ``D * T_c`` (s)."""
        return self.n_chirps * self.chirp_interval_s

    @property
    def n_antennas(self) -> int:
        """Number of receive antennas ``A``."""
        return int(self.rx_positions_m.shape[0])

    @classmethod
    def from_calibration(
        cls,
        calibration: Any,
        *,
        n_samples: int,
        n_chirps: int,
        sample_rate_hz: float | None = None,
        where: str = "radar calibration",
    ) -> FmcwParams:
        """Parameters of a radar from its format-v1 calibration entry.

        The calibration stores what is needed to read cubes (see
        :data:`CALIBRATION_KEYS`); the frame size comes from the cube shape
        ``[R, D, A]`` (``n_samples = R``, ``n_chirps = D``). The chirp interval
        follows from ``doppler_bin_mps = lambda / (2 D T_c)``. The sample rate
        is not stored: without ``sample_rate_hz`` the sweep is taken to fill the
        chirp interval (``f_s = N / T_c``), which only affects the residual video
        phase and range migration within a chirp.

        Parameters
        ----------
        calibration : Mapping or object
            The radar's entry (a dict with the format's keys, or a
            ``RadarCalibration`` with those attributes).
        n_samples, n_chirps : int
            Fast-time samples and chirps per frame (the cube's ``R`` and ``D``).
        sample_rate_hz : float, optional
        where : str
            Names the source in error messages (e.g. ``"sensors.left"``).

        Raises
        ------
        ZendarFormatError
            Listing every missing or inconsistent value.
        """

        def get(key: str) -> Any:
            if isinstance(calibration, Mapping):
                return calibration.get(key)
            return getattr(calibration, key, None)

        values = {key: get(key) for key in CALIBRATION_KEYS}
        problems = [f"{where}: missing key {key!r}" for key, value in values.items() if value is None]
        for key in CALIBRATION_KEYS[:4]:
            if values[key] is None:
                continue
            try:
                values[key] = float(values[key])
            except (TypeError, ValueError):
                problems.append(f"{where}.{key}: expected a positive number, found {values[key]!r}")
                continue
            if not (np.isfinite(values[key]) and values[key] > 0):
                problems.append(f"{where}.{key}: expected a positive number, found {values[key]!r}")
        if problems:
            raise ZendarFormatError("invalid radar calibration: " + "; ".join(problems), problems)
        expected_bin = SPEED_OF_LIGHT_MPS / (2.0 * values["bandwidth_hz"])
        if abs(values["range_bin_m"] / expected_bin - 1.0) > _RANGE_BIN_TOLERANCE:
            problems.append(
                f"{where}.range_bin_m: {values['range_bin_m']:g} m disagrees with c / (2 bandwidth_hz) = {expected_bin:g} m"
            )
        wavelength = SPEED_OF_LIGHT_MPS / values["center_frequency_hz"]
        chirp_interval_s = wavelength / (2.0 * int(n_chirps) * values["doppler_bin_mps"]) if int(n_chirps) > 0 else 1.0
        try:
            params = cls(
                center_frequency_hz=values["center_frequency_hz"],
                bandwidth_hz=values["bandwidth_hz"],
                sample_rate_hz=n_samples / chirp_interval_s if sample_rate_hz is None else sample_rate_hz,
                n_samples=n_samples,
                n_chirps=n_chirps,
                chirp_interval_s=chirp_interval_s,
                rx_positions_m=values["rx_positions_m"],
            )
        except ZendarFormatError as err:
            problems.extend(f"{where}: {p}" for p in err.problems)
        if problems:
            raise ZendarFormatError("invalid radar calibration: " + "; ".join(problems), problems)
        return params

    def to_calibration(self) -> dict[str, Any]:
        """The format-v1 radar calibration keys (JSON-ready: floats and nested lists)."""
        return {
            "center_frequency_hz": self.center_frequency_hz,
            "bandwidth_hz": self.bandwidth_hz,
            "range_bin_m": self.range_bin_m,
            "doppler_bin_mps": self.doppler_bin_mps,
            "rx_positions_m": self.rx_positions_m.tolist(),
        }

    def uniform_linear_array(self) -> bool:
        """Whether the receivers are equally spaced along one line (what spatial smoothing needs)."""
        rx = self.rx_positions_m
        if rx.shape[0] < 2:
            return True
        step = np.diff(rx, axis=0)
        return bool(np.allclose(step, step[0], atol=1e-9 * max(1.0, float(np.abs(rx).max()))))


def beat_signal_exact(
    params: FmcwParams,
    scatterer_positions_m: np.ndarray,
    scatterer_velocities_mps: np.ndarray,
    amplitudes: np.ndarray,
    *,
    t0_s: float = 0.0,
    dtype: type = np.complex128,
) -> np.ndarray:
    """Beat signal of point scatterers, evaluated sample by sample from the true geometry.

    Each scatterer moves at constant velocity, ``x(t) = x0 + v * t``, where ``t``
    is ``t0_s + m * T_c + k / f_s`` for chirp ``m`` and sample ``k``; the
    round-trip delay ``tau = (|x(t)| + |x(t) - p_a|) / c`` is recomputed for
    every sample, so range migration within and across chirps, Doppler, the
    antenna phase and the residual video phase are all exact under the
    convention (the geometry is taken at the sample time; the change of
    position during the flight time itself, ~1e-7 s, is neglected).

    Parameters
    ----------
    params : FmcwParams
    scatterer_positions_m : numpy.ndarray
        ``[P, 3]`` (or ``[3]``) positions at ``t = 0`` in the radar sensor frame, metres.
    scatterer_velocities_mps : numpy.ndarray
        ``[P, 3]`` (or ``[3]``) velocities in the radar sensor frame, m/s.
    amplitudes : numpy.ndarray
        ``[P]`` complex (or real) amplitudes ``A``, applied as given (no path loss).
    t0_s : float
        Time of the first sample of chirp 0 relative to the epoch of the positions, s.
    dtype : numpy dtype
        ``complex128`` (default) or ``complex64``; the sum is always formed in float64.

    Returns
    -------
    numpy.ndarray
        ``[n_chirps, n_samples, A]`` complex samples.

    Raises
    ------
    ValueError
        When array shapes disagree.
    """
    pos = np.atleast_2d(np.asarray(scatterer_positions_m, dtype=np.float64))
    vel = np.atleast_2d(np.asarray(scatterer_velocities_mps, dtype=np.float64))
    amp = np.atleast_1d(np.asarray(amplitudes, dtype=np.complex128))
    if pos.ndim != 2 or pos.shape[1] != 3:
        raise ValueError(f"scatterer_positions_m must be [P, 3], got shape {np.shape(scatterer_positions_m)}")
    if vel.shape != pos.shape:
        raise ValueError(f"scatterer_velocities_mps must be {pos.shape}, got shape {np.shape(scatterer_velocities_mps)}")
    if amp.shape != (pos.shape[0],):
        raise ValueError(f"amplitudes must be [{pos.shape[0]}], got shape {np.shape(amplitudes)}")
    if np.dtype(dtype) not in (np.dtype(np.complex64), np.dtype(np.complex128)):
        raise ValueError(f"dtype must be complex64 or complex128, got {dtype}")

    c = SPEED_OF_LIGHT_MPS
    fc, slope = params.center_frequency_hz, params.slope_hz_per_s
    t_fast = np.arange(params.n_samples) / params.sample_rate_hz  # [N]
    t_slow = t0_s + np.arange(params.n_chirps) * params.chirp_interval_s  # [D]
    t_abs = (t_slow[:, None] + t_fast[None, :])[..., None]  # [D, N, 1]
    rx = params.rx_positions_m  # [A, 3]
    out = np.zeros((params.n_chirps, params.n_samples, params.n_antennas), dtype=np.complex128)
    for x0, v, a in zip(pos, vel, amp):
        x = x0 + v * t_abs  # [D, N, 3]
        tx_range = np.linalg.norm(x, axis=-1, keepdims=True)  # [D, N, 1]
        rx_range = np.linalg.norm(x[:, :, None, :] - rx, axis=-1)  # [D, N, A]
        tau = (tx_range + rx_range) / c
        # Cycles, not radians, so the large carrier term is reduced mod 1 before
        # multiplying by 2*pi (keeps ~1e-7 rad precision at 77 GHz and 100 m).
        cycles = fc * tau + slope * tau * t_fast[None, :, None] - 0.5 * slope * tau * tau
        out += a * np.exp(2j * np.pi * np.mod(cycles, 1.0))
    return out.astype(dtype, copy=False)
