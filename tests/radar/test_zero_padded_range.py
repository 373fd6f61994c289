"""Range of a point target through a zero-padded range FFT, against the FMCW beat-frequency formula.

The raw frame is written here from the physics, not with the package's signal model: a static
point at range ``R`` gives the beat frequency ``f_b = 2 S R / c`` (``S`` the chirp slope), so
sample ``k`` of every chirp is ``exp(j 2π f_b k / f_s)`` times a constant phase. With the range
FFT padded to ``4 N`` points the cells are ``c / (2 B) / 4`` apart, and the detection must report
``R`` to within one of them.
"""

from __future__ import annotations

import numpy as np
import pytest
from tests.radar.radar_helpers import ula_params

from zendar_dataset.radar.cfar import detect
from zendar_dataset.radar.fmcw import SPEED_OF_LIGHT_MPS
from zendar_dataset.radar.batched_chain import RadarChain
from zendar_dataset.radar.range_doppler import range_doppler

PAD = 4


def _raw(params, range_m: float, rng: np.random.Generator) -> np.ndarray:
    """``[n_chirps, n_samples, A]`` complex64: one static point on boresight plus weak noise."""
    slope_hz_per_s = params.bandwidth_hz / (params.n_samples / params.sample_rate_hz)
    beat_hz = 2.0 * slope_hz_per_s * range_m / SPEED_OF_LIGHT_MPS
    t_s = np.arange(params.n_samples) / params.sample_rate_hz
    phase = 4.0 * np.pi * params.center_frequency_hz * range_m / SPEED_OF_LIGHT_MPS
    chirp = np.exp(1j * (2.0 * np.pi * beat_hz * t_s + phase))
    shape = (params.n_chirps, params.n_samples, params.n_antennas)
    noise = 1e-3 * (rng.standard_normal(shape) + 1j * rng.standard_normal(shape))
    return (np.broadcast_to(chirp[None, :, None], shape) + noise).astype(np.complex64)


@pytest.mark.parametrize("range_m", [2.3, 6.85, 10.1])
def test_a_zero_padded_cube_reports_the_true_range(range_m):
    params = ula_params(n_samples=64, n_chirps=32)
    bin_m = SPEED_OF_LIGHT_MPS / (2.0 * params.bandwidth_hz)  # 0.1874 m for 800 MHz; 12 m unambiguous
    assert range_m < 0.9 * params.n_samples * bin_m
    raw = _raw(params, range_m, np.random.default_rng(1))
    cube = range_doppler(raw, n_range_bins=PAD * params.n_samples)
    dets = detect(cube, params, method="ca", guard=(2, 2), train=(8, 4), pfa=1e-6)
    strongest = int(np.argmax(dets.power))
    assert dets.doppler_bin[strongest] == params.n_chirps // 2
    assert abs(dets.range_m[strongest] - range_m) <= bin_m / PAD
    # The batched chain reads the spacing the same way.
    chain = RadarChain(params, cfar=dict(method="ca", guard=(2, 2), train=(8, 4), pfa=1e-6))
    batch = chain.from_cubes(cube[None])
    best = int(np.argmax(batch.power.numpy()))
    assert abs(float(batch.range_m[best]) - range_m) <= bin_m / PAD
