"""Fast synthesis of range-Doppler cubes and per-chirp range profiles.

The exact model (:func:`zendar_dataset.radar.fmcw.beat_signal_exact` followed by
:func:`zendar_dataset.radar.range_doppler.range_doppler`) sums every scatterer
into every fast-time sample and then runs a 2-D FFT.  A point scatterer's cube is
nearly separable instead: within chirp ``m`` it is a tone at the fractional
range bin ``x_m = N (S tau_m + f_c dtau/dt) / f_s`` (beat frequency plus the
range-Doppler coupling of the carrier), whose windowed DFT is the window's
response ``W(x_m - r)``; it carries the carrier and residual-video phase
``f_c tau_m - S tau_m^2 / 2`` of that chirp; and the antennas add the steering
phase.  So per scatterer we evaluate ``W`` only on the ``2K + 1`` bins around the
peak for every chirp (this keeps range migration across the frame exact) and
add it, times the chirp's phase and each antenna's steering, into a
range-compressed slow-time cube ``[N, D, A]``; one Doppler FFT of that cube
finishes the job (the FFT is linear, so this equals a Doppler FFT per scatterer).
Cost: ``S (2K + 1) D A`` multiply-adds and ``N A`` short FFTs instead of
``S N D A`` sample evaluations and a 2-D FFT.

The per-scatterer loops are numba kernels: the same sums written with numpy
broadcasting build ``[S, K, D, A]`` complex128 temporaries (~60 MB per demo
cube) and spent most of the simulator's time moving them through memory.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numba
import numpy as np
import scipy.fft

from zendar_dataset.radar.fmcw import SPEED_OF_LIGHT_MPS, FmcwParams
from zendar_dataset.radar.range_doppler import WindowSpec, window_values
from zendar_dataset.sim.rotate import dot

BOLTZMANN_J_PER_K = 1.380649e-23
DEFAULT_HALF_WIDTH_BINS = 6


class RangeResponse:
    """Response of a windowed ``N``-point DFT to a complex tone between bins.

    ``W(nu) = sum_k w_k exp(j 2 pi k nu / N)`` is the DFT output ``nu`` bins
    below the tone.  ``W`` is tabulated once (without its linear phase
    ``pi nu (N - 1) / N``, which the synthesis kernels restore exactly) at
    ``1 / oversample`` bin steps for ``|nu| <= half_width + 1``, and so is
    ``dW/dnu``; the kernels interpolate the tables linearly (:func:`_interpolate`);
    the tabulated part is smooth, so the interpolation error is ~1e-5 relative.

    Parameters
    ----------
    window : numpy.ndarray
        ``[N]`` float64 window weights.
    half_width_bins : int
        ``K``: bins kept on each side of the peak.
    oversample : int
        Table points per bin.
    """

    def __init__(self, window: np.ndarray, half_width_bins: int = DEFAULT_HALF_WIDTH_BINS, oversample: int = 64) -> None:
        self.window = np.asarray(window, dtype=np.float64)
        self.n = int(self.window.shape[0])
        self.half_width_bins = int(half_width_bins)
        self.oversample = int(oversample)
        self.nu_min = -(self.half_width_bins + 2.0)
        nu = self.nu_min + np.arange(int(2 * (self.half_width_bins + 2) * self.oversample) + 1) / self.oversample
        k = np.arange(self.n)
        centered = (k - (self.n - 1) / 2.0)[:, None] * nu[None, :]
        terms = self.window[:, None] * np.exp(2j * np.pi * centered / self.n)  # [N, T]
        self.table = _exact_sum(terms)
        # d/dnu of the tabulated part, for first-order shifts of the tone.
        self.table_rate = _exact_sum(terms * (2j * np.pi * (k - (self.n - 1) / 2.0) / self.n)[:, None])


def _exact_sum(terms: np.ndarray) -> np.ndarray:
    """Correctly rounded sums over axis 0 of complex ``terms [N, T]`` (``math.fsum`` per part), ``[T]`` complex128.

    Not ``window @ kernel``: BLAS splits that sum between its threads, so the
    tables (and every cube built from them) changed in the last bit with the
    number of BLAS threads of the process; a correctly rounded sum depends on
    nothing but the terms.
    """
    real = [math.fsum(column) for column in np.ascontiguousarray(terms.real.T).tolist()]
    imag = [math.fsum(column) for column in np.ascontiguousarray(terms.imag.T).tolist()]
    return np.array(real) + 1j * np.array(imag)


@numba.njit(cache=True, inline="always")
def _interpolate(table: np.ndarray, nu_min: float, oversample: int, nu: float) -> complex:
    """A ``RangeResponse`` table at ``nu`` bins, linearly interpolated and clamped to the table's ends."""
    pos = min(max((nu - nu_min) * oversample, 0.0), table.shape[0] - 1.000001)
    lower = int(pos)
    frac = pos - lower
    return table[lower] * (1.0 - frac) + table[lower + 1] * frac


@lru_cache(maxsize=16)
def _range_response(window_key: tuple, half_width_bins: int) -> RangeResponse:
    return RangeResponse(np.asarray(window_key), half_width_bins)


def range_response(window: np.ndarray, half_width_bins: int = DEFAULT_HALF_WIDTH_BINS) -> RangeResponse:
    """Cached :class:`RangeResponse` for a window array."""
    return _range_response(tuple(np.asarray(window, dtype=np.float64).tolist()), int(half_width_bins))


def _delays(params: FmcwParams, positions_sensor: np.ndarray, receiver_m: np.ndarray) -> np.ndarray:
    """Round-trip delay (s) transmitter (origin) -> point -> receiver, ``[...]``."""
    tx = np.linalg.norm(positions_sensor, axis=-1)
    rx = np.linalg.norm(positions_sensor - receiver_m, axis=-1)
    return (tx + rx) / SPEED_OF_LIGHT_MPS


def _tone_bins_and_cycles(params: FmcwParams, tau: np.ndarray, tau_rate: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fractional range bin and carrier + residual-video-phase cycles of each chirp."""
    slope = params.slope_hz_per_s
    bins = (slope * tau + params.center_frequency_hz * tau_rate) * params.n_samples / params.sample_rate_hz
    cycles = np.mod(params.center_frequency_hz * tau, 1.0) - np.mod(0.5 * slope * tau * tau, 1.0)
    return bins, cycles


def synthesize_cube(
    params: FmcwParams,
    positions_sensor: np.ndarray,
    amplitudes: np.ndarray,
    *,
    range_window: WindowSpec = "hann",
    doppler_window: WindowSpec = "hann",
    half_width_bins: int = DEFAULT_HALF_WIDTH_BINS,
) -> np.ndarray:
    """Range-Doppler cube of point scatterers, without noise (fast model).

    Equals ``range_doppler(beat_signal_exact(...))`` to ~1e-3 relative L2 (see
    tests/sim/test_radar_model.py) for scatterers whose response peaks inside
    the range axis.

    Parameters
    ----------
    params : FmcwParams
    positions_sensor : numpy.ndarray
        ``[S, D, 3]`` float64 position of each scatterer at the start of each
        chirp, radar sensor frame (x boresight, y left, z up), metres.
    amplitudes : numpy.ndarray
        ``[S]`` complex amplitudes per fast-time sample (as in ``beat_signal_exact``).
    range_window, doppler_window : str, None or array
        The windows of :func:`~zendar_dataset.radar.range_doppler.range_doppler`.
    half_width_bins : int
        Range bins kept on each side of a scatterer's peak.

    Returns
    -------
    numpy.ndarray
        ``[N, D, A]`` complex64 cube, Doppler bin ``D // 2`` at zero radial velocity.
    """
    positions = np.asarray(positions_sensor, dtype=np.float64)
    n_chirps, n_samples, n_rx = params.n_chirps, params.n_samples, params.n_antennas
    if positions.ndim != 3 or positions.shape[1:] != (n_chirps, 3):
        raise ValueError(f"positions_sensor must be [S, {n_chirps}, 3], got {positions.shape}")
    amplitudes = np.asarray(amplitudes, dtype=np.complex128).reshape(-1)
    if amplitudes.shape[0] != positions.shape[0]:
        raise ValueError(f"amplitudes must be [{positions.shape[0]}], got {amplitudes.shape}")
    cube = np.zeros((n_samples, n_chirps, n_rx), dtype=np.complex64)
    if positions.shape[0] == 0:
        return cube
    rx = params.rx_positions_m
    reference = rx.mean(axis=0)
    tau = _delays(params, positions, reference)  # [S, D]
    tau_rate = np.gradient(tau, params.chirp_interval_s, axis=1) if n_chirps > 1 else np.zeros_like(tau)
    bins, cycles = _tone_bins_and_cycles(params, tau, tau_rate)

    # Steering phase of each antenna relative to the reference, from the exact
    # delays at the middle chirp (the direction changes little within a frame).
    # The antennas' beat frequencies also differ by ~0.01 bin (S * dtau), which
    # is worth ~1 % of the cube: it enters to first order through dW/dnu.
    mid = positions[:, n_chirps // 2, :]
    delay_offset = _delays(params, mid[:, None, :], rx[None, :, :]) - tau[:, n_chirps // 2, None]  # [S, A]
    steering = np.exp(2j * np.pi * np.mod(params.center_frequency_hz * delay_offset, 1.0))
    bin_offset = params.slope_hz_per_s * delay_offset * n_samples / params.sample_rate_hz  # [S, A]

    response = range_response(window_values(range_window, n_samples), half_width_bins)
    peak = np.rint(bins[:, n_chirps // 2]).astype(np.int64)  # [S]
    w_d = window_values(doppler_window, n_chirps)
    slow = amplitudes[:, None] * w_d[None, :] * np.exp(2j * np.pi * cycles)  # [S, D]
    if n_chirps % 2 == 0:
        # (-1)^m in slow time is the fftshift of an even-length Doppler axis.
        slow = slow * np.where(np.arange(n_chirps) % 2 == 0, 1.0, -1.0)[None, :]
    slow_time = np.zeros((n_samples, n_chirps, n_rx), dtype=np.complex128)
    _add_scatterer_chirps(
        slow_time, slow, bins, peak, steering, bin_offset, int(half_width_bins),
        response.table, response.table_rate, response.nu_min, response.oversample,
    )
    spectra = scipy.fft.fft(slow_time, axis=1, workers=1)
    if n_chirps % 2:
        spectra = scipy.fft.fftshift(spectra, axes=1)
    cube[:] = spectra
    return cube


@numba.njit(cache=True)
def _add_scatterer_chirps(
    out, slow, bins, peak, steering, bin_offset, half_width, table, table_rate, nu_min, oversample
):
    """``out[r, m, a] += slow[s, m] (W + W' bin_offset[s, a])(bins[s, m] - r) steering[s, a]``.

    Over the ``2 K + 1`` kept bins ``r`` around ``peak[s]`` (wrapped: the DFT is
    periodic); ``W`` and ``dW/dnu`` come from the ``RangeResponse`` tables.
    """
    n_samples, n_chirps, n_rx = out.shape
    linear = np.pi * (n_samples - 1) / n_samples
    # nu drops by one bin per kept bin: the linear phase advances by a constant factor.
    step = complex(np.cos(linear), -np.sin(linear))
    for s in range(slow.shape[0]):
        for m in range(n_chirps):
            nu = bins[s, m] - (peak[s] - half_width)
            phase = complex(np.cos(linear * nu), np.sin(linear * nu))
            for k in range(-half_width, half_width + 1):
                row = (peak[s] + k) % n_samples
                centered = _interpolate(table, nu_min, oversample, nu)
                h = centered * phase
                h_rate = (_interpolate(table_rate, nu_min, oversample, nu) + 1j * linear * centered) * phase
                base = slow[s, m] * h
                rate = slow[s, m] * h_rate
                for a in range(n_rx):
                    out[row, m, a] += (base + rate * bin_offset[s, a]) * steering[s, a]
                nu -= 1.0
                phase *= step


def synthesize_range_profiles(
    params: FmcwParams,
    positions_sensor: np.ndarray,
    velocities_sensor: np.ndarray,
    amplitudes: np.ndarray,
    receiver_m: np.ndarray,
    *,
    range_window: WindowSpec = "hann",
    half_width_bins: int = DEFAULT_HALF_WIDTH_BINS,
) -> np.ndarray:
    """Per-chirp range profiles of point scatterers for one receiver (fast model).

    Equals ``range_profiles(beat_signal_exact(...))[..., a]`` for that receiver.

    Parameters
    ----------
    params : FmcwParams
    positions_sensor : numpy.ndarray
        ``[P, S, 3]`` float64 scatterer positions at the start of each of ``P``
        chirps (pulses), sensor frame, metres.
    velocities_sensor : numpy.ndarray
        ``[P, S, 3]`` velocities relative to the sensor, sensor frame, m/s
        (they set the range-Doppler coupling within the chirp).
    amplitudes : numpy.ndarray
        ``[P, S]`` complex amplitudes.
    receiver_m : numpy.ndarray
        ``[3]`` receive-antenna position in the sensor frame.

    Returns
    -------
    numpy.ndarray
        ``[P, N]`` complex64 profiles.
    """
    positions = np.asarray(positions_sensor, dtype=np.float64)
    velocities = np.asarray(velocities_sensor, dtype=np.float64)
    n_pulses, n_samples = positions.shape[0], params.n_samples
    receiver = np.asarray(receiver_m, dtype=np.float64)
    tx = np.linalg.norm(positions, axis=-1)
    to_rx = positions - receiver
    rx = np.linalg.norm(to_rx, axis=-1)
    tau = (tx + rx) / SPEED_OF_LIGHT_MPS  # [P, S]
    tau_rate = (
        dot(positions, velocities) / np.maximum(tx, 1e-9)
        + dot(to_rx, velocities) / np.maximum(rx, 1e-9)
    ) / SPEED_OF_LIGHT_MPS
    bins, cycles = _tone_bins_and_cycles(params, tau, tau_rate)
    response = range_response(window_values(range_window, n_samples), half_width_bins)
    values = np.asarray(amplitudes, dtype=np.complex128) * np.exp(2j * np.pi * cycles)  # [P, S]
    out = np.zeros((n_pulses, n_samples), dtype=np.complex128)
    _add_scatterer_pulses(
        out, values, bins, np.rint(bins).astype(np.int64), int(half_width_bins),
        response.table, response.nu_min, response.oversample,
    )
    return out.astype(np.complex64)


@numba.njit(cache=True)
def _add_scatterer_pulses(out, values, bins, peak, half_width, table, nu_min, oversample):
    """``out[p, r] += values[p, s] W(bins[p, s] - r)`` over the ``2 K + 1`` bins ``r`` around ``peak[p, s]``."""
    n_samples = out.shape[1]
    linear = np.pi * (n_samples - 1) / n_samples
    # nu drops by one bin per kept bin: the linear phase advances by a constant factor.
    step = complex(np.cos(linear), -np.sin(linear))
    for p in range(values.shape[0]):
        for s in range(values.shape[1]):
            nu = bins[p, s] - (peak[p, s] - half_width)
            phase = values[p, s] * complex(np.cos(linear * nu), np.sin(linear * nu))
            for k in range(-half_width, half_width + 1):
                out[p, (peak[p, s] + k) % n_samples] += _interpolate(table, nu_min, oversample, nu) * phase
                nu -= 1.0
                phase *= step


@dataclass(frozen=True)
class RadarFrontEnd:
    """Link budget and antenna pattern of one radar.

    The one-way power pattern is ``cos(az)^q_az * cos(el)^q_el`` (zero behind the
    radar), with ``q`` chosen so it is 3 dB down at ``half_beam_*_deg``; the
    two-way amplitude gain is that pattern times the peak gain.

    Attributes
    ----------
    tx_power_w : float
        Transmit power, W.
    antenna_gain_dbi : float
        Peak gain of each of the transmit and receive antennas, dBi.
    noise_figure_db : float
        Receiver noise figure, dB.
    half_beam_azimuth_deg, half_beam_elevation_deg : float
        One-way 3 dB half-widths, degrees.
    """

    tx_power_w: float = 0.01
    antenna_gain_dbi: float = 12.0
    noise_figure_db: float = 12.0
    half_beam_azimuth_deg: float = 60.0
    half_beam_elevation_deg: float = 15.0
    temperature_k: float = 290.0

    def pattern(self, positions_sensor: np.ndarray) -> np.ndarray:
        """Two-way amplitude pattern (1 at boresight) of points ``[..., 3]`` in the sensor frame."""
        p = np.asarray(positions_sensor, dtype=np.float64)
        horizontal = np.hypot(p[..., 0], p[..., 1])
        cos_az = np.where(horizontal > 0, p[..., 0] / np.maximum(horizontal, 1e-12), 0.0)
        cos_el = horizontal / np.maximum(np.linalg.norm(p, axis=-1), 1e-12)
        q_az = math.log(0.5) / math.log(math.cos(math.radians(self.half_beam_azimuth_deg)))
        q_el = math.log(0.5) / math.log(math.cos(math.radians(self.half_beam_elevation_deg)))
        return np.clip(cos_az, 0.0, None) ** q_az * cos_el**q_el

    def amplitude(self, params: FmcwParams, rcs_m2: np.ndarray, positions_sensor: np.ndarray) -> np.ndarray:
        """Per-sample amplitude ``sqrt(P_r)`` (sqrt W) from the radar equation, ``[...]``."""
        p = np.asarray(positions_sensor, dtype=np.float64)
        distance = np.maximum(np.linalg.norm(p, axis=-1), 0.5)
        gain = 10.0 ** (self.antenna_gain_dbi / 10.0)
        power = (
            self.tx_power_w * gain**2 * params.wavelength_m**2 * np.asarray(rcs_m2, dtype=np.float64)
            / ((4.0 * math.pi) ** 3 * distance**4)
        )
        return np.sqrt(power) * self.pattern(p)

    def noise_power_w(self, params: FmcwParams) -> float:
        """Thermal noise power per complex fast-time sample, ``k T F f_s`` (W)."""
        return BOLTZMANN_J_PER_K * self.temperature_k * 10.0 ** (self.noise_figure_db / 10.0) * params.sample_rate_hz


def thermal_noise(rng: np.random.Generator, shape: tuple[int, ...], power_w: float) -> np.ndarray:
    """Circular complex Gaussian noise of ``power_w`` per sample, complex64."""
    scale = np.float32(math.sqrt(power_w / 2.0))
    noise = rng.standard_normal((*shape, 2), dtype=np.float32) * scale
    return noise.view(np.complex64)[..., 0]
