"""SAR images from simulated per-pulse range profiles, through the package's backprojection.

Per image: the synthetic aperture is the stretch of the ego path of length
``aperture_m`` centred on the ego position at the image time; pulses are
placed along it at a uniform spacing (below); their range profiles are
synthesised with the same physics as the cubes (static and moving scatterers,
antenna pattern, path loss, Swerling fluctuation, thermal noise, range-Doppler
coupling), each pulse standing for every chirp of every receiver
(:func:`chirps_per_pulse`, :func:`presum_factors`; the receivers as one channel at
the array's centre, docs/simulator.md); and
:func:`zendar_dataset.sar.backprojection.backproject` forms the image, tapered by
:data:`AZIMUTH_WINDOW` along the aperture, from the *written* (noisy) tracklog
poses, with no compensation of moving objects.

Pulse spacing: the two-way phase ``4 pi R / lambda`` of a static scatterer
changes along the track with spatial frequency ``2 u / lambda``, ``u`` the cosine
of the angle between the track and the line of sight, ``|u| <= 1`` in every
direction.  Pulses spaced ``lambda / 4`` apart (at the top of the sweep, with a
10 % margin) therefore sample every direction without aliasing, behind the
radar included, so no pixel of the image holds a grating lobe.  The spacing is
uniform along the track: pulses are not rounded to the chirp grid, whose
alternating 3- and 4-chirp gaps (the chirps come every ``v T_c``) spread every
strong scatterer into a ring at its range.  Each pulse is simulated at the
exact time the ego passes its position; the chirps come every ``v T_c < lambda /
4`` (the ego drives slower than the radar's unambiguous speed
``lambda / (4 T_c)``), so the chirp train holds the same along-track signal and
an interpolating processor can form these pulses from it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.fft

from zendar_dataset.radar.fmcw import SPEED_OF_LIGHT_MPS, FmcwParams
from zendar_dataset.radar.range_doppler import window_values
from zendar_dataset.sar.backprojection import backproject
from zendar_dataset.sar.grid import ImageGrid
from zendar_dataset.sim.rotate import rotate

MIN_PULSES = 8
# The slow-time taper of every simulated image (recorded in the calibration as sar_azimuth_window).
AZIMUTH_WINDOW = "hann"
# Pulses sample the static band 10 % finer than its Nyquist rate.
NYQUIST_MARGIN = 1.1


def pulse_spacing_m(params: FmcwParams) -> float:
    """Along-track pulse spacing that samples static returns from every direction without aliasing (metres).

    ``lambda / (4 * NYQUIST_MARGIN)`` at the sweep's top frequency ``f_c + B``, whose
    wavelength is the shortest in the pulse.
    """
    top_wavelength_m = SPEED_OF_LIGHT_MPS / (params.center_frequency_hz + params.bandwidth_hz)
    return top_wavelength_m / (4.0 * NYQUIST_MARGIN)


def aperture_times(
    time_s: np.ndarray, distance_m: np.ndarray, t_center_s: float, aperture_m: float, spacing_m: float,
    chirp_interval_s: float, max_half_span_s: float = 1.0,
) -> np.ndarray:
    """Pulse times of the aperture centred on ``t_center_s``: uniform along the path, ``spacing_m`` apart.

    ``distance_m`` is the ego's travelled distance at ``time_s`` (non-decreasing).
    The aperture is shortened when the ego does not cover ``aperture_m`` within
    ``max_half_span_s`` on either side (slow or stopped ego); its pulses are then
    centred in the distance covered.  When the ego covers less than
    ``MIN_PULSES`` spacings, there is no synthetic aperture: a burst of
    ``MIN_PULSES`` chirps (``chirp_interval_s`` apart) around the image time.
    """
    d_center = float(np.interp(t_center_s, time_s, distance_m))
    d_lo = max(d_center - aperture_m / 2, float(np.interp(t_center_s - max_half_span_s, time_s, distance_m)))
    d_hi = min(d_center + aperture_m / 2, float(np.interp(t_center_s + max_half_span_s, time_s, distance_m)))
    if d_hi - d_lo < spacing_m * MIN_PULSES:
        return t_center_s + (np.arange(MIN_PULSES) - MIN_PULSES / 2) * chirp_interval_s
    n = int(np.floor((d_hi - d_lo) / spacing_m + 1e-9)) + 1
    targets = 0.5 * (d_lo + d_hi) + (np.arange(n) - (n - 1) / 2) * spacing_m
    return _first_times(time_s, distance_m, targets)


def _first_times(time_s: np.ndarray, distance_m: np.ndarray, targets_m: np.ndarray) -> np.ndarray:
    """The first time each distance is reached (the distance is flat while the ego stands)."""
    after = np.clip(np.searchsorted(distance_m, targets_m, side="left"), 1, distance_m.shape[0] - 1)
    d0, d1 = distance_m[after - 1], distance_m[after]
    fraction = np.clip((targets_m - d0) / np.maximum(d1 - d0, 1e-300), 0.0, 1.0)
    return time_s[after - 1] + fraction * (time_s[after] - time_s[after - 1])


def chirps_per_pulse(time_s: np.ndarray, distance_m: np.ndarray, pulse_times_s: np.ndarray, spacing_m: float,
                     chirp_interval_s: float) -> np.ndarray:
    """Chirps ``[P]`` each pulse presums: those sent while the ego is within half a spacing of its position.

    A processor integrates every chirp by presumming: it low-pass filters the chirp train in slow
    time to the band of static returns and resamples it at the pulses' positions, so each pulse
    carries the chirps of its stretch of track (more while the ego is slow, all of a stop's),
    and the thermal noise falls by their number. Single chirps (``aperture_times``' burst when the
    ego does not move): 1 each.
    """
    along = np.interp(pulse_times_s, time_s, distance_m)
    if pulse_times_s.shape[0] < 2 or np.ptp(along) < spacing_m:
        return np.ones(pulse_times_s.shape[0])
    dwell = (_first_times(time_s, distance_m, along + spacing_m / 2)
             - _first_times(time_s, distance_m, along - spacing_m / 2))
    return np.maximum(dwell / chirp_interval_s, 1.0)


def presum_factors(doppler_hz: np.ndarray, pulse_times_s: np.ndarray, ego_speed_mps: np.ndarray, spacing_m: float,
                   chirp_interval_s: float) -> np.ndarray:
    """What presumming does to each return ``[S, P]`` (complex): 1 for every static one, 0 or a phase for movers.

    The chirp train samples a return of Doppler ``doppler_hz`` ``[S, P]`` at ``1 / T_c``, folding
    it into ``[-1 / (2 T_c), 1 / (2 T_c))``; the presum filter passes the band its pulses sample,
    ``|f| <= v / (2 spacing)`` (``v`` the ego speed at each pulse ``[P]``; static returns lie inside,
    ``|f| <= 2 v / lambda``), and removes the rest; a folded return that passes carries its folded
    frequency, so its phase at the pulse time ``t`` turns by ``-2 pi k t / T_c`` (``k`` the fold).
    """
    folds = np.rint(doppler_hz * chirp_interval_s)
    folded = doppler_hz - folds / chirp_interval_s
    passed = np.abs(folded) <= (np.asarray(ego_speed_mps) / (2.0 * spacing_m))[None, :]
    turns = np.mod(folds * (np.asarray(pulse_times_s) / chirp_interval_s)[None, :], 1.0)
    return np.where(passed, np.exp(-2j * np.pi * turns), 0.0)


def sar_waveform(cube_params: FmcwParams, bandwidth_hz: float, max_range_m: float) -> FmcwParams:
    """The waveform SAR images are formed from: the cube's carrier, chirp interval and receivers,
    swept over ``bandwidth_hz``, with enough fast-time samples to reach ``max_range_m``.

    The ADC window fills the same 85 % of the chirp interval as the cube's, so the
    sample rate (and with it the thermal noise ``k T F f_s`` per sample) grows with
    the number of samples.
    """
    range_bin_m = SPEED_OF_LIGHT_MPS / (2.0 * bandwidth_hz)
    n_samples = scipy.fft.next_fast_len(int(np.ceil(max_range_m / range_bin_m)) + 2 * MIN_PULSES)
    return FmcwParams(
        center_frequency_hz=cube_params.center_frequency_hz,
        bandwidth_hz=float(bandwidth_hz),
        sample_rate_hz=n_samples / (0.85 * cube_params.chirp_interval_s),
        n_samples=int(n_samples),
        n_chirps=cube_params.n_chirps,
        chirp_interval_s=cube_params.chirp_interval_s,
        rx_positions_m=cube_params.rx_positions_m,
    )


@dataclass(frozen=True)
class SarGeometry:
    """Where a radar's SAR image lies in the ego frame at the image time.

    The image plane is horizontal at the radar's mounting height; rows (``i``)
    run along the ego x axis, columns (``j``) along ego y (left).

    Attributes
    ----------
    center_ego : numpy.ndarray
        ``[3]`` centre of the image in the ego frame, metres.
    pixel_m : float
        Pixel size along both axes, metres.
    shape : tuple of int
        ``(H, W)`` pixels.
    """

    center_ego: np.ndarray
    pixel_m: float
    shape: tuple[int, int]

    @classmethod
    def covering(
        cls,
        position_ego: np.ndarray,
        boresight_ego: np.ndarray,
        half_fov_rad: float,
        coverage_m: float,
        pixel_m: float,
        extra_points_ego: np.ndarray | None = None,
    ) -> SarGeometry:
        """The smallest ego-axis-aligned image that holds the radar's field of view out to ``coverage_m``.

        The field of view is the horizontal sector of half-angle ``half_fov_rad``
        around the boresight, apex at the radar; ``extra_points_ego`` ``[K, 2 or 3]``
        (e.g. the lane ahead) are covered too.
        """
        position = np.asarray(position_ego, dtype=np.float64)
        heading = float(np.arctan2(boresight_ego[1], boresight_ego[0]))
        # The sector's bounding box: its apex, its arc's ends and the arc's axis crossings.
        angles = [heading - half_fov_rad, heading + half_fov_rad]
        angles += [k * np.pi / 2 for k in range(-4, 5) if abs(np.angle(np.exp(1j * (k * np.pi / 2 - heading)))) < half_fov_rad]
        arc = position[None, :2] + coverage_m * np.stack([np.cos(angles), np.sin(angles)], axis=1)
        points = [position[None, :2], arc]
        if extra_points_ego is not None:
            points.append(np.asarray(extra_points_ego, dtype=np.float64).reshape(-1, np.shape(extra_points_ego)[-1])[:, :2])
        points = np.concatenate(points)
        low, high = points.min(axis=0), points.max(axis=0)
        shape = tuple(int(n) for n in np.ceil((high - low) / pixel_m).astype(np.int64) + 1)
        center = np.array([*(0.5 * (low + high)), position[2]])
        return cls(center, float(pixel_m), (shape[0], shape[1]))

    @property
    def corners_ego(self) -> np.ndarray:
        """``[4, 3]`` the image's corner pixel centres in the ego frame."""
        half = 0.5 * (np.array(self.shape) - 1) * self.pixel_m
        signs = np.array([[-1, -1], [-1, 1], [1, -1], [1, 1]], dtype=np.float64)
        return self.center_ego[None, :] + np.concatenate([signs * half, np.zeros((4, 1))], axis=1)

    def grid_enu(self, enu_r_ego: np.ndarray, enu_t_ego: np.ndarray) -> ImageGrid:
        """The image grid in ENU for the ego pose ``(enu_r_ego [3, 3], enu_t_ego [3])``."""
        return ImageGrid.axis_aligned(
            center=rotate(enu_r_ego, self.center_ego) + enu_t_ego,
            u=enu_r_ego[:, 0],
            v=enu_r_ego[:, 1],
            pixel_m=self.pixel_m,
            shape=self.shape,
        )


def profiles_for_backprojection(params: FmcwParams, profiles: np.ndarray, upsample: int = 4) -> tuple[np.ndarray, float, float]:
    """Prepare raw-DFT range profiles ``[P, N]`` for backprojection.

    Backprojection interpolates profiles linearly in range, which would pull a
    Hann main lobe (~2 bins wide) towards its nearest sample by up to half a
    bin; the profiles are therefore first upsampled ``upsample`` times (exactly,
    by zero-padding the fast-time samples).  The raw DFT of a tone also carries a
    linear phase of ``pi (N - 1) / N`` per original bin away from the tone (the
    window starts at sample 0) and the residual video phase ``-pi S tau^2``:
    multiplying fine bin ``r`` by ``exp(j pi r (N - 1) / (N U))`` centres the
    window, leaving a smooth envelope, at the price of the carrier now being the
    sweep's mid frequency ``f_c + S (N - 1) / (2 f_s)``; multiplying by
    ``exp(j pi S tau_r^2)`` removes the residual video phase of each bin's range.

    Returns
    -------
    profiles : numpy.ndarray
        ``[P, N * upsample]`` complex64.
    range_bin_m : float
        Spacing of the upsampled profiles.
    center_frequency_hz : float
        The carrier to backproject with.
    """
    n = params.n_samples
    n_fine = n * int(upsample)
    samples = scipy.fft.ifft(profiles, axis=1)
    fine = scipy.fft.fft(samples, n=n_fine, axis=1)
    r = np.arange(n_fine)
    bin_m = params.range_bin_m / upsample
    tau = 2.0 * r * bin_m / SPEED_OF_LIGHT_MPS
    correction = np.exp(1j * np.pi * (r * (n - 1) / n_fine + np.mod(params.slope_hz_per_s * tau * tau, 2.0)))
    frequency = params.center_frequency_hz + params.slope_hz_per_s * (n - 1) / (2.0 * params.sample_rate_hz)
    return (fine * correction[None, :]).astype(np.complex64), bin_m, frequency


def form_image(
    params: FmcwParams,
    profiles: np.ndarray,
    phase_centers: np.ndarray,
    grid: ImageGrid,
    device: str | None = None,
) -> np.ndarray:
    """Backproject raw-DFT range profiles ``[P, N]`` from phase centres ``[P, 3]`` onto ``grid``.

    The pulses are tapered along the aperture by :data:`AZIMUTH_WINDOW` and the profiles are
    normalised by the range window's sum, so a point scatterer of per-sample amplitude ``a``
    peaks near ``a`` times the sum of the azimuth weights (``a * P / 2`` for Hann).
    ``device`` ``None`` or ``"cpu"`` uses the numba kernel; a CUDA device (``"cuda"``) the
    torch backend there, which computes the same float32 sum (equal to rounding).
    Returns complex64 ``[H, W]`` (numpy).
    """
    prepared, bin_m, frequency = profiles_for_backprojection(params, profiles)
    scale = 1.0 / float(np.sum(window_values("hann", params.n_samples)))
    return backproject(
        prepared * np.float32(scale), phase_centers, grid, range_bin_m=bin_m, center_frequency_hz=frequency,
        azimuth_window=AZIMUTH_WINDOW, backend="numba" if device in (None, "cpu") else "torch",
        device=None if device == "cpu" else device,
    )
