"""Fast factorised backprojection against the exact kernel on closed-form point targets:
peak within 0.5 dB, position within 1 pixel, PSLR and ISLR within 1 dB."""

import numpy as np
import pytest

from tests.sar.point_target import point_target_profiles
from zendar_dataset.sar.backprojection import backproject
from zendar_dataset.sar.ffbp import backproject_ffbp
from zendar_dataset.sar.grid import ImageGrid

SPEED_OF_LIGHT_MPS = 299_792_458.0
FREQUENCY_HZ = 77e9
BANDWIDTH_HZ = 3.75e9
WAVELENGTH_M = SPEED_OF_LIGHT_MPS / FREQUENCY_HZ
BIN_M = 0.01


def _scene(aperture_m, targets, grid_center, pixel_m, shape, grid_yaw_rad):
    n = int(aperture_m / (WAVELENGTH_M / 4))
    s = np.linspace(-aperture_m / 2, aperture_m / 2, n)
    # A slightly curving, slightly climbing track (an ego on a bend), not along the grid's axes.
    track = np.stack([s, 0.01 * s**2, 0.002 * s], axis=1) + [5.0, -3.0, 0.5]
    ranges = np.arange(0.0, 45.0, BIN_M)
    profiles = point_target_profiles(
        track, targets, np.ones(len(targets)), ranges, bandwidth_hz=BANDWIDTH_HZ, center_frequency_hz=FREQUENCY_HZ,
        num_fast_samples=1024,
    )
    c, sn = np.cos(grid_yaw_rad), np.sin(grid_yaw_rad)
    grid = ImageGrid.axis_aligned(grid_center, [c, sn, 0.0], [-sn, c, 0.0], pixel_m, shape)
    return profiles, track, grid


def _lobe_metrics(cut):
    """(PSLR dB, ISLR dB) of a 1-D power cut: main lobe between the first minima around the peak."""
    peak = int(np.argmax(cut))
    left = peak
    while left > 0 and cut[left - 1] < cut[left]:
        left -= 1
    right = peak
    while right < cut.size - 1 and cut[right + 1] < cut[right]:
        right += 1
    main = cut[left:right + 1]
    side = np.concatenate([cut[:left], cut[right + 1:]])
    return 10 * np.log10(side.max() / cut[peak]), 10 * np.log10(side.sum() / main.sum())


@pytest.mark.slow
@pytest.mark.parametrize("aperture_m", [0.5, 2.0])
def test_ffbp_matches_the_exact_kernel_on_point_targets(aperture_m):
    # Two targets at 14 and 22 m, each imaged on its own fine grid (1 cm pixels resolve the lobes).
    for target in (np.array([7.0, 11.0, 0.5]), np.array([1.0, 18.0, 0.5])):
        profiles, track, grid = _scene(aperture_m, target[None], target + [0.013, -0.021, 0.0], 0.01, (96, 96), 0.35)
        exact = np.abs(backproject(profiles, track, grid, range_bin_m=BIN_M, center_frequency_hz=FREQUENCY_HZ)) ** 2
        fast = np.abs(backproject_ffbp(profiles, track, grid, range_bin_m=BIN_M, center_frequency_hz=FREQUENCY_HZ,
                                       tile_px=32, final_tile_px=4)) ** 2
        assert 10 * np.log10(fast.max() / exact.max()) == pytest.approx(0.0, abs=0.5)
        pe = np.array(np.unravel_index(np.argmax(exact), exact.shape))
        pf = np.array(np.unravel_index(np.argmax(fast), fast.shape))
        assert np.all(np.abs(pe - pf) <= 1)
        # Against the true position too (the grid is rotated: the pixel is found by the image model).
        ti, tj, _ = grid.world_to_pixel(target)
        assert abs(pf[0] - ti) <= 1.5 and abs(pf[1] - tj) <= 1.5
        for axis in (0, 1):
            cut_e = exact[pe[0], :] if axis else exact[:, pe[1]]
            cut_f = fast[pf[0], :] if axis else fast[:, pf[1]]
            pslr_e, islr_e = _lobe_metrics(cut_e)
            pslr_f, islr_f = _lobe_metrics(cut_f)
            assert pslr_f == pytest.approx(pslr_e, abs=1.0)
            assert islr_f == pytest.approx(islr_e, abs=1.0)


@pytest.mark.slow
def test_ffbp_image_agrees_with_the_exact_one_over_a_multi_target_scene():
    rng = np.random.default_rng(4)
    targets = np.stack([rng.uniform(-4, 4, 12), rng.uniform(14, 26, 12), np.full(12, 0.5)], axis=1)
    profiles, track, grid = _scene(1.0, targets, [0.0, 20.0, 0.5], 0.04, (160, 224), -0.2)
    exact = backproject(profiles, track, grid, range_bin_m=BIN_M, center_frequency_hz=FREQUENCY_HZ)
    fast = backproject_ffbp(profiles, track, grid, range_bin_m=BIN_M, center_frequency_hz=FREQUENCY_HZ)
    assert exact.dtype == fast.dtype == np.complex64 and fast.shape == grid.shape
    # Relative L2 difference: beams are re-interpolated at each level (a few % of the image energy).
    assert np.linalg.norm(fast - exact) / np.linalg.norm(exact) < 0.2
    # Every target's brightest pixel is where the exact kernel puts it.
    for target in targets:
        i, j, _ = grid.world_to_pixel(target)
        i, j = int(round(float(i))), int(round(float(j)))
        if 3 <= i < grid.shape[0] - 3 and 3 <= j < grid.shape[1] - 3:
            we, wf = np.abs(exact[i - 3:i + 4, j - 3:j + 4]), np.abs(fast[i - 3:i + 4, j - 3:j + 4])
            assert 20 * np.log10(wf.max() / we.max()) == pytest.approx(0.0, abs=1.0)


def test_tiles_next_to_the_track_are_exact():
    # Pixels within a few metres of the track cannot share beams: they are backprojected pulse by pulse.
    target = np.array([5.3, -1.5, 0.5])
    profiles, track, grid = _scene(0.5, target[None], target, 0.02, (64, 64), 0.0)
    exact = backproject(profiles, track, grid, range_bin_m=BIN_M, center_frequency_hz=FREQUENCY_HZ)
    fast = backproject_ffbp(profiles, track, grid, range_bin_m=BIN_M, center_frequency_hz=FREQUENCY_HZ)
    np.testing.assert_allclose(fast, exact, atol=2e-4 * np.abs(exact).max())


def test_bad_arguments_are_named():
    profiles, track, grid = _scene(0.1, np.array([[0.0, 10.0, 0.5]]), [0.0, 10.0, 0.5], 0.04, (8, 8), 0.0)
    with pytest.raises(ValueError, match="tile_px must be a power of two"):
        backproject_ffbp(profiles, track, grid, range_bin_m=BIN_M, center_frequency_hz=FREQUENCY_HZ, tile_px=24)
    with pytest.raises(ValueError, match="final_tile_px .* must not exceed"):
        backproject_ffbp(profiles, track, grid, range_bin_m=BIN_M, center_frequency_hz=FREQUENCY_HZ, tile_px=8,
                         final_tile_px=16)
    with pytest.raises(ValueError, match="positions_m has 3 pulses"):
        backproject_ffbp(profiles, track[:3], grid, range_bin_m=BIN_M, center_frequency_hz=FREQUENCY_HZ)
