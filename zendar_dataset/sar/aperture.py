"""The slow-time (azimuth) taper of a synthetic aperture and the cross-range resolution it gives.

A point scatterer's backprojected response across its line of sight is the Fourier transform of
the weights its pulses carry along the aperture: uniform weights give a sinc with −13 dB
sidelobes decaying as 1/f, which spread every strong scatterer along its own range circle; a
window that falls smoothly to zero at the aperture's ends (Hann: −31.5 dB first sidelobe,
−18 dB per octave after it) confines it, at the price of a wider main lobe.  Same trade as the
range window in fast time.
"""

from __future__ import annotations

import math

import numpy as np

AZIMUTH_WINDOWS: dict[str, float] = {"rectangular": 0.8859, "hann": 1.4406}
"""Windows by name, with the 3-dB width of their response in units of ``1 / L`` (``L`` the
aperture length): the continuous window's Fourier transform, ``sinc`` and
``sinc(x) / (1 − x²)``, at half power."""


def _check_window(window: str) -> None:
    if window not in AZIMUTH_WINDOWS:
        raise ValueError(f"azimuth window must be one of {sorted(AZIMUTH_WINDOWS)}, got {window!r}")


def azimuth_weights(positions_m: np.ndarray, window: str) -> np.ndarray:
    """Weight ``[P]`` float32 of each pulse: ``window`` over the aperture, evaluated at its position.

    The position along the aperture is the projection on the pulses' principal axis (the track,
    straight or gently curved), so the taper follows the distance travelled whatever the pulse
    spacing; ``"hann"`` is ``sin²(π s / L)``, zero at both ends. An aperture of no length (the
    radar did not move) gets uniform weights.

    Raises
    ------
    ValueError
        For an unknown window name.
    """
    _check_window(window)
    positions = np.asarray(positions_m, dtype=np.float64)
    if window == "rectangular" or positions.shape[0] < 2:
        return np.ones(positions.shape[0], dtype=np.float32)
    centred = positions - positions.mean(axis=0)
    _, _, axes = np.linalg.svd(centred, full_matrices=False)
    along = centred @ axes[0]
    length = float(along.max() - along.min())
    if length <= 0.0:
        return np.ones(positions.shape[0], dtype=np.float32)
    return (np.sin(np.pi * (along - along.min()) / length) ** 2).astype(np.float32)


def cross_range_resolution_m(range_m: float, wavelength_m: float, aperture_m: float, angle_rad: float,
                             window: str) -> float:
    """3-dB width of a point's response across its line of sight, metres.

    ``k · λ · R / (2 · L · sin θ)`` (paper §1.1.1 for the angle, ``R`` times it across the line of
    sight), ``k`` the window's factor in :data:`AZIMUTH_WINDOWS` (rectangular 0.886, Hann 1.441),
    ``θ`` the angle between the aperture and the line of sight.
    """
    _check_window(window)
    return AZIMUTH_WINDOWS[window] * wavelength_m * range_m / (2.0 * aperture_m * math.sin(angle_rad))
