"""Shared parameters for the radar tests."""

import numpy as np

from zendar_dataset.radar.fmcw import SPEED_OF_LIGHT_MPS, FmcwParams


def ula_params(n_samples: int = 64, n_chirps: int = 32, n_antennas: int = 4) -> FmcwParams:
    """A 77 GHz radar with a half-wavelength uniform linear array along y."""
    wavelength = SPEED_OF_LIGHT_MPS / 77e9
    rx = np.zeros((n_antennas, 3))
    rx[:, 1] = np.arange(n_antennas) * wavelength / 2
    return FmcwParams(
        center_frequency_hz=77e9,
        bandwidth_hz=800e6,
        sample_rate_hz=10e6,
        n_samples=n_samples,
        n_chirps=n_chirps,
        chirp_interval_s=10e-6 + n_samples / 10e6,
        rx_positions_m=rx,
    )
