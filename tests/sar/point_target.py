"""Closed-form range profiles of point targets, independent of the package.

The range-compressed profile of a monostatic FMCW pulse seen from ``position`` is
the DFT of the windowed beat tone, evaluated at range ``r`` (a DTFT, so any sample
spacing works). With the sweep centred on the carrier, sample ``k`` at frequency
``f_k = f_c + B·u_k``, ``u_k = (k − (N − 1)/2)/N``:

    X(r) = Σ_k w_k · exp(j·4π·R·f_k/c) · exp(−j·4π·r·(f_k − f_c)/c)
         = exp(j·4π·R/λ) · Σ_k exp(j·4π·(R − r)·B·u_k/c)        (unwindowed, w_k = 1)
    = exp(j·4π·R/λ) · sin(N·x/2) / sin(x/2),   x = 4π·(R − r)·B/(c·N),

peaking at r = R with the carrier phase exp(+j·4π·R/λ) of docs/architecture.md.
The Dirichlet kernel's 3-dB width is 0.886·c/(2B) for large N.
"""

from __future__ import annotations

import numpy as np

SPEED_OF_LIGHT_MPS = 299_792_458.0


def point_target_profiles(
    positions_m: np.ndarray,
    targets_m: np.ndarray,
    amplitudes: np.ndarray,
    sample_ranges_m: np.ndarray,
    *,
    bandwidth_hz: float,
    center_frequency_hz: float,
    num_fast_samples: int = 256,
) -> np.ndarray:
    """Profiles [P, len(sample_ranges_m)] complex64 of targets [K, 3] seen from [P, 3]."""
    n = num_fast_samples
    wavelength_m = SPEED_OF_LIGHT_MPS / center_frequency_hz
    profiles = np.zeros((len(positions_m), len(sample_ranges_m)), dtype=np.complex128)
    for target, amplitude in zip(np.atleast_2d(targets_m), np.atleast_1d(amplitudes)):
        ranges_m = np.linalg.norm(target - positions_m, axis=1)  # [P]
        lag_m = ranges_m[:, None] - sample_ranges_m[None, :]  # [P, S]
        half_x = 2 * np.pi * bandwidth_hz / (SPEED_OF_LIGHT_MPS * n) * lag_m
        sin_half_x = np.sin(half_x)
        small = np.abs(sin_half_x) < 1e-12
        kernel = np.where(small, n, np.sin(n * half_x) / np.where(small, 1.0, sin_half_x))
        profiles += amplitude * np.exp(1j * 4 * np.pi * ranges_m / wavelength_m)[:, None] * kernel
    return profiles.astype(np.complex64)


def reference_backprojection(
    profiles: np.ndarray,
    positions_m: np.ndarray,
    pixels_m: np.ndarray,
    *,
    range_offset_m: float,
    range_bin_m: float,
    center_frequency_hz: float,
) -> np.ndarray:
    """Direct float64 backprojection, one pulse at a time, with numpy.interp."""
    sample_ranges_m = range_offset_m + range_bin_m * np.arange(profiles.shape[1])
    wavelength_m = SPEED_OF_LIGHT_MPS / center_frequency_hz
    image = np.zeros(pixels_m.shape[:-1], dtype=np.complex128)
    for profile, position in zip(profiles, positions_m):
        r = np.linalg.norm(pixels_m - position, axis=-1)
        value = np.interp(r, sample_ranges_m, profile.real, left=0, right=0) + 1j * np.interp(
            r, sample_ranges_m, profile.imag, left=0, right=0
        )
        image += value * np.exp(-1j * 4 * np.pi * r / wavelength_m)
    return image


def half_power_width(values: np.ndarray, step: float) -> float:
    """Width of the -3 dB main lobe of |values| sampled at ``step``, linearly interpolated."""
    power = np.abs(values) ** 2
    peak = int(np.argmax(power))
    half = power[peak] / 2
    left = peak
    while left > 0 and power[left - 1] >= half:
        left -= 1
    right = peak
    while right < len(power) - 1 and power[right + 1] >= half:
        right += 1
    if left == 0 or right == len(power) - 1:
        raise AssertionError("main lobe not inside the sampled cut")
    # Fractional crossings between the last sample above and the first below.
    left_x = left - (power[left] - half) / (power[left] - power[left - 1])
    right_x = right + (power[right] - half) / (power[right] - power[right + 1])
    return (right_x - left_x) * step
