"""Labelling helpers on a synthetic image with a known bright spot and noise floor."""

from __future__ import annotations

import numpy as np
import pytest

from zendar_dataset.sar import ImageGrid
from zendar_dataset.sar.labeling import local_snr_db, noise_power, project_points, snr_at_points_db

NOISE_POWER = 4.0
SPOT_IJ = (60, 110)
SPOT_SNR_DB = 30.0


@pytest.fixture(scope="module")
def scene():
    rng = np.random.default_rng(3)
    shape = (200, 240)
    image = np.sqrt(NOISE_POWER / 2) * (rng.standard_normal(shape) + 1j * rng.standard_normal(shape))
    image[SPOT_IJ] = np.sqrt(NOISE_POWER * 10 ** (SPOT_SNR_DB / 10)) * np.exp(0.3j)
    # A few strong scatterers must not move the noise estimate.
    image[rng.integers(0, 200, 300), rng.integers(0, 240, 300)] *= 100
    grid = ImageGrid.axis_aligned([5.0, 12.0, 0.0], [0, 1, 0], [1, 0, 0], 0.04, shape)
    return image.astype(np.complex64), grid


def test_noise_power_is_robust(scene):
    image, _ = scene
    assert noise_power(image) == pytest.approx(NOISE_POWER, rel=0.05)
    assert noise_power(np.abs(image)) == pytest.approx(noise_power(image))


def test_project_points_round_trip_and_inside(scene):
    _, grid = scene
    pixels = np.array([[60.0, 110.0], [0.2, 239.4], [-1.0, 5.0], [10.0, 240.6], [100.0, 100.0]])
    points = grid.pixel_to_world(pixels[:, 0], pixels[:, 1])
    points[4] += 3.0 * grid.normal
    pixel_ij, inside = project_points(grid, points, max_out_of_plane_m=1.0)
    np.testing.assert_allclose(pixel_ij, pixels, atol=1e-9)
    np.testing.assert_array_equal(inside, [True, True, False, False, False])


def test_local_snr_at_bright_spot_and_in_noise(scene):
    image, _ = scene
    # On the spot, one pixel off (inside the window), and far away in noise.
    pixel_ij = np.array([[60.0, 110.0], [61.3, 108.8], [150.0, 30.0], [-3.0, 0.0]])
    snr_db = local_snr_db(image, pixel_ij, radius_px=2)
    assert snr_db[0] == pytest.approx(SPOT_SNR_DB, abs=0.3)
    assert snr_db[1] == pytest.approx(SPOT_SNR_DB, abs=0.3)
    # Max of 25 exponential powers: a few dB above the floor, far below the spot.
    assert 0.0 < snr_db[2] < 12.0
    assert np.isnan(snr_db[3])
    # A window that excludes the spot does not see it.
    assert local_snr_db(image, [[63.0, 110.0]], radius_px=1)[0] < 15.0


def test_snr_at_points_combines_projection_and_window(scene):
    image, grid = scene
    points = grid.pixel_to_world(np.array([60.0, 150.0, 400.0]), np.array([110.0, 30.0, 3.0]))
    snr_db = snr_at_points_db(image, grid, points, radius_px=1)
    assert snr_db[0] == pytest.approx(SPOT_SNR_DB, abs=0.3)
    assert snr_db[1] < 12.0
    assert np.isnan(snr_db[2])
    # An explicit noise power replaces the estimate: 10x the power is 10 dB less.
    explicit = snr_at_points_db(image, grid, points[:1], radius_px=1, noise=10 * NOISE_POWER)
    assert explicit[0] == pytest.approx(SPOT_SNR_DB - 10, abs=0.3)


def test_sar_frames_refuse_a_cache_of_no_frames():
    from zendar_dataset.sar.frames import SarFrames

    class NoSar:
        def sensors(self, kind):
            return []

    for bad in (0, -1, 1.5, "2"):
        with pytest.raises(ValueError, match="keep_frames"):
            SarFrames(NoSar(), keep_frames=bad)
    assert SarFrames(NoSar(), keep_frames=None).sensors == []
