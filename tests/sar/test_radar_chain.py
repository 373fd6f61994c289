"""The radar chain's range profiles focus through backprojection (shared phase convention).

Independent of tests/sar/point_target.py: raw samples from ``radar.fmcw.beat_signal_exact``
(true geometry per sample, residual video phase included), range-compressed by
``radar.range_doppler.range_profiles``, then imaged.
"""

from __future__ import annotations

import numpy as np
import pytest

from zendar_dataset.sar import ImageGrid, backproject

fmcw = pytest.importorskip("zendar_dataset.radar.fmcw")
range_doppler = pytest.importorskip("zendar_dataset.radar.range_doppler")

UPSAMPLE = 4


@pytest.mark.parametrize("backend", ["numba", "torch"])
def test_moving_radar_focuses_a_static_point(backend):
    params = fmcw.FmcwParams(
        center_frequency_hz=77e9,
        bandwidth_hz=1e9,
        sample_rate_hz=5e6,
        n_samples=128,
        n_chirps=200,
        chirp_interval_s=5e-5,
        rx_positions_m=np.zeros((1, 3)),
    )
    # The radar moves along its y axis by λ/4 per chirp; in the radar frame the
    # scatterer moves the other way.
    speed_mps = params.wavelength_m / 4 / params.chirp_interval_s
    target_m = np.array([8.0, 0.05, 0.0])
    raw = fmcw.beat_signal_exact(params, target_m, [0.0, -speed_mps, 0.0], [1.0])
    profiles = range_doppler.range_profiles(raw, range_window=None, n_range_bins=UPSAMPLE * params.n_samples)[..., 0]

    # Scene frame = radar frame at t = 0; phase centre at mid-sweep of each chirp.
    chirp_mid_s = np.arange(params.n_chirps) * params.chirp_interval_s + params.sweep_duration_s / 2
    positions_m = np.zeros((params.n_chirps, 3))
    positions_m[:, 1] = speed_mps * chirp_mid_s
    grid = ImageGrid.axis_aligned(target_m + [0.03, -0.05, 0.0], [1, 0, 0], [0, 1, 0], 0.04, (21, 21))
    image = backproject(
        profiles.astype(np.complex64),
        positions_m,
        grid,
        range_bin_m=params.range_bin_m / UPSAMPLE,
        center_frequency_hz=params.center_frequency_hz,
        backend=backend,
    )
    peak = np.unravel_index(np.argmax(np.abs(image)), image.shape)
    i, j, _ = grid.world_to_pixel(target_m)
    assert abs(peak[0] - i) <= 1 and abs(peak[1] - j) <= 1
    # Focused: the peak holds most of the coherent sum of |profile| at the target.
    assert np.abs(image).max() > 0.8 * params.n_chirps * params.n_samples
