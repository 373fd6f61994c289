"""Direction of arrival from antenna signals written from the geometry, not from ``steering_vectors``.

A snapshot built with the package's own steering vectors hides a sign error (the estimator
undoes what the builder did). Here each antenna's signal is the two-way path to a point 40 m
away: transmitter at the origin, receiver ``a`` at ``p_a``, phase ``2π (|x| + |x - p_a|) / λ``
(docs/architecture.md: a signal ``exp(+j 2π f_c τ)``), so an antenna nearer the target leads
in path and lags in phase, ``≈ -2π (u·p_a) / λ``. Azimuth is positive to the left (+y).
"""

from __future__ import annotations

import numpy as np
import pytest
import torch
from tests.radar.radar_helpers import ula_params

from zendar_dataset.radar.doa import estimate_azimuth
from zendar_dataset.radar.batched_chain import RadarChain

RANGE_M = 40.0
AZIMUTHS_DEG = (23.0, -31.0, 7.5, -4.0)  # left, right, near boresight on both sides


def _snapshots(params, azimuth_deg: float, n_snapshots: int, rng: np.random.Generator) -> np.ndarray:
    """``[K, A]`` complex: one target at ``azimuth_deg`` with random complex amplitude per snapshot, 30 dB SNR."""
    az = np.radians(azimuth_deg)
    target = RANGE_M * np.array([np.cos(az), np.sin(az), 0.0])
    rx = params.rx_positions_m
    path_m = np.linalg.norm(target) + np.linalg.norm(target[None] - rx, axis=1)  # [A]
    response = np.exp(2j * np.pi * path_m / params.wavelength_m)
    amplitude = rng.standard_normal(n_snapshots) + 1j * rng.standard_normal(n_snapshots)
    noise = 0.03 / np.sqrt(2) * (rng.standard_normal((n_snapshots, rx.shape[0])) + 1j * rng.standard_normal((n_snapshots, rx.shape[0])))
    return amplitude[:, None] * response[None] + noise


@pytest.mark.parametrize("method", ["bartlett", "capon", "music"])
def test_azimuth_sign_and_value_from_geometric_snapshots(method):
    params = ula_params(n_antennas=8)
    rng = np.random.default_rng(11)
    truth = np.radians(AZIMUTHS_DEG)
    snapshots = np.stack([_snapshots(params, az, 16, rng) for az in AZIMUTHS_DEG])  # [N, K, A]
    estimate = estimate_azimuth(snapshots, params.rx_positions_m, params.wavelength_m, method=method)
    assert np.all(np.sign(estimate) == np.sign(truth)), np.degrees(estimate)
    np.testing.assert_allclose(np.degrees(estimate), AZIMUTHS_DEG, atol=0.5)


def test_the_batched_chain_reads_the_same_sign():
    params = ula_params(n_antennas=8)
    rng = np.random.default_rng(12)
    single = np.stack([_snapshots(params, az, 1, rng)[0] for az in AZIMUTHS_DEG])  # [N, A]
    chain = RadarChain(params, grid_step_deg=0.1)
    estimate = chain.azimuth(torch.as_tensor(single, dtype=torch.complex64)).numpy()
    np.testing.assert_allclose(np.degrees(estimate), AZIMUTHS_DEG, atol=1.0)
