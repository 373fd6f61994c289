"""Backprojection against closed-form point targets, a float64 reference and itself across backends."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from tests.sar.point_target import (
    SPEED_OF_LIGHT_MPS,
    half_power_width,
    point_target_profiles,
    reference_backprojection,
)
from zendar_dataset.sar import ImageGrid, backproject
from zendar_dataset.sar.aperture import azimuth_weights, cross_range_resolution_m

CENTER_FREQUENCY_HZ = 77e9
WAVELENGTH_M = SPEED_OF_LIGHT_MPS / CENTER_FREQUENCY_HZ
BANDWIDTH_HZ = 1e9
RANGE_RESOLUTION_M = SPEED_OF_LIGHT_MPS / (2 * BANDWIDTH_HZ)
# Profiles are sampled 4x finer than the resolution so linear interpolation is accurate.
RANGE_BIN_M = RANGE_RESOLUTION_M / 4
RANGE_OFFSET_M = 3.0
NUM_SAMPLES = 300
APERTURE_M = 0.4
# Pulse spacing just under λ/4: no grating lobes in any direction.
NUM_PULSES = 420
# 3-dB width of the unwindowed (rectangular) sinc response, in resolution cells.
RECT_3DB_FACTOR = 0.886

BACKENDS = ["numba", "torch"]


def aperture_positions(num_pulses: int = NUM_PULSES) -> np.ndarray:
    positions = np.zeros((num_pulses, 3))
    positions[:, 0] = np.linspace(-APERTURE_M / 2, APERTURE_M / 2, num_pulses)
    return positions


def profiles_for(positions: np.ndarray, targets: np.ndarray, amplitudes) -> np.ndarray:
    return point_target_profiles(
        positions,
        targets,
        np.asarray(amplitudes),
        RANGE_OFFSET_M + RANGE_BIN_M * np.arange(NUM_SAMPLES),
        bandwidth_hz=BANDWIDTH_HZ,
        center_frequency_hz=CENTER_FREQUENCY_HZ,
        num_fast_samples=128,
    )


def run(profiles, positions, grid, backend, azimuth_window="rectangular"):
    return backproject(
        profiles,
        positions,
        grid,
        range_bin_m=RANGE_BIN_M,
        center_frequency_hz=CENTER_FREQUENCY_HZ,
        range_offset_m=RANGE_OFFSET_M,
        azimuth_window=azimuth_window,
        backend=backend,
    )


@pytest.fixture(scope="module")
def broadside_scene():
    positions = aperture_positions()
    target = np.array([0.013, 8.0, 0.0])
    return positions, target, profiles_for(positions, target[None], [1.0])


@pytest.mark.parametrize("backend", BACKENDS)
def test_point_target_peak_within_one_pixel(broadside_scene, backend):
    positions, target, profiles = broadside_scene
    # Paper pixel size (4 cm); 50 columns is not a whole number of row segments.
    grid = ImageGrid.axis_aligned(target + [0.05, -0.07, 0.0], [0, 1, 0], [1, 0, 0], 0.04, (40, 50))
    image = run(profiles, positions, grid, backend)
    assert image.shape == (40, 50) and image.dtype == np.complex64
    peak = np.unravel_index(np.argmax(np.abs(image)), image.shape)
    i, j, _ = grid.world_to_pixel(target)
    assert abs(peak[0] - i) <= 1 and abs(peak[1] - j) <= 1
    # Coherent gain at the target itself: every pulse adds in phase (less the
    # linear-interpolation loss between profile samples), with the phase removed.
    at_target = run(profiles, positions, ImageGrid.axis_aligned(target, [0, 1, 0], [1, 0, 0], 0.04, (1, 1)), backend)
    assert np.abs(at_target[0, 0]) > 0.95 * NUM_PULSES * 128
    assert abs(np.angle(at_target[0, 0])) < 0.05


def _cut(target, direction, step_m, half_width):
    """A one-row grid through ``target`` along ``direction``."""
    n = 2 * half_width + 1
    return ImageGrid.axis_aligned(target, np.cross([0, 0, 1], direction), direction, step_m, (1, n))


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("squint_deg", [90.0, 50.0])
def test_resolution_matches_paper_formulas(backend, squint_deg):
    """3-dB widths vs paper §1.1.1 times the rectangular window's 0.886.

    Range: ΔR = c / 2B. Azimuth: Δθ = c / (2·f·L·sin θ), θ the angle between the
    aperture and the line of sight; across the line of sight at range R that is
    R·Δθ metres.
    """
    positions = aperture_positions()
    theta = np.deg2rad(squint_deg)
    range_m = 8.0
    target = range_m * np.array([np.cos(theta), np.sin(theta), 0.0])
    profiles = profiles_for(positions, target[None], [1.0])
    line_of_sight = target / range_m
    across = np.cross([0, 0, 1], line_of_sight)

    range_cut = run(profiles, positions, _cut(target, line_of_sight, 0.002, 120), backend)[0]
    measured_range_m = half_power_width(range_cut, 0.002)
    expected_range_m = RECT_3DB_FACTOR * RANGE_RESOLUTION_M
    assert measured_range_m == pytest.approx(expected_range_m, rel=0.2)

    azimuth_cut = run(profiles, positions, _cut(target, across, 0.001, 150), backend)[0]
    measured_azimuth_m = half_power_width(azimuth_cut, 0.001)
    expected_azimuth_m = (
        RECT_3DB_FACTOR * range_m * SPEED_OF_LIGHT_MPS / (2 * CENTER_FREQUENCY_HZ * APERTURE_M * np.sin(theta))
    )
    assert measured_azimuth_m == pytest.approx(expected_azimuth_m, rel=0.2)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("squint_deg", [90.0, 50.0])
def test_hann_azimuth_window_gives_the_windowed_cross_range_resolution(backend, squint_deg):
    """Hann taper along the aperture: 3-dB width across the line of sight within 1 % of
    1.441 · λR / (2L sin θ) (the continuous Hann window's transform at half power)."""
    positions = aperture_positions()
    theta = np.deg2rad(squint_deg)
    range_m = 8.0
    target = range_m * np.array([np.cos(theta), np.sin(theta), 0.0])
    profiles = profiles_for(positions, target[None], [1.0])
    across = np.cross([0, 0, 1], target / range_m)
    step_m = 0.0005
    cut = run(profiles, positions, _cut(target, across, step_m, 300), backend, azimuth_window="hann")[0]
    expected_m = cross_range_resolution_m(range_m, WAVELENGTH_M, APERTURE_M, theta, "hann")
    assert half_power_width(cut, step_m) == pytest.approx(expected_m, rel=0.01)
    rectangular = run(profiles, positions, _cut(target, across, step_m, 300), backend)[0]
    assert half_power_width(rectangular, step_m) == pytest.approx(
        cross_range_resolution_m(range_m, WAVELENGTH_M, APERTURE_M, theta, "rectangular"), rel=0.01
    )


def test_azimuth_weights_follow_the_position_along_the_aperture():
    # Uneven spacing along a tilted track: the taper is the window of the distance travelled.
    along = np.sort(np.random.default_rng(3).uniform(0.0, 0.4, 50))
    direction = np.array([0.6, 0.8, 0.0])
    weights = azimuth_weights(along[:, None] * direction + [5.0, -2.0, 1.0], "hann")
    expected = np.sin(np.pi * (along - along[0]) / (along[-1] - along[0])) ** 2
    np.testing.assert_allclose(weights, expected, atol=1e-6)
    assert np.all(azimuth_weights(np.zeros((4, 3)), "hann") == 1.0)
    with pytest.raises(ValueError, match="azimuth window"):
        azimuth_weights(np.zeros((4, 3)), "taylor")


@pytest.fixture(scope="module")
def busy_scene():
    """Several targets plus noise: a non-trivial image to compare backends on."""
    rng = np.random.default_rng(7)
    positions = aperture_positions(200) + rng.normal(0, 0.002, (200, 3))
    targets = np.array([[0.3, 6.0, 0.1], [-0.5, 7.2, 0.0], [0.1, 7.25, -0.2], [1.0, 9.0, 0.0]])
    profiles = profiles_for(positions, targets, [1.0, 0.5, 0.8j, 2.0])
    profiles += (rng.normal(0, 3, profiles.shape) + 1j * rng.normal(0, 3, profiles.shape)).astype(np.complex64)
    grid = ImageGrid.axis_aligned([0.2, 7.5, 0.0], [0, 1, 0], [1, 0.1, 0], 0.03, (70, 90))
    return positions, profiles, grid


def _relative_error(image, reference):
    image = image.cpu().numpy() if isinstance(image, torch.Tensor) else image
    return np.abs(image - reference).max() / np.abs(reference).max()


def test_backends_match_float64_reference_and_each_other(busy_scene):
    positions, profiles, grid = busy_scene
    reference = reference_backprojection(
        profiles,
        positions,
        grid.pixel_centers(),
        range_offset_m=RANGE_OFFSET_M,
        range_bin_m=RANGE_BIN_M,
        center_frequency_hz=CENTER_FREQUENCY_HZ,
    )
    numba_image = run(profiles, positions, grid, "numba")
    torch_image = run(profiles, positions, grid, "torch")
    assert _relative_error(numba_image, reference) < 1e-4
    assert _relative_error(torch_image, reference) < 1e-4
    assert _relative_error(numba_image, torch_image.astype(np.complex128)) < 1e-4


def test_numba_tiles_change_no_bit_of_the_image(busy_scene, monkeypatch):
    """Every pixel sums its pulses in the same order whatever the tile: one row segment per tile
    (the kernel's former layout), odd tiles that leave a partial last tile, and the default agree
    bit for bit; and the default agrees with the float64 reference."""
    from zendar_dataset.sar import backprojection_numba

    positions, profiles, grid = busy_scene
    images = {}
    for rows in (1, 7, backprojection_numba.ROWS_PER_TILE, 128):
        monkeypatch.setattr(backprojection_numba, "ROWS_PER_TILE", rows)
        images[rows] = run(profiles, positions, grid, "numba")
    first = images[1].view(np.uint64)
    for rows, image in images.items():
        assert np.array_equal(image.view(np.uint64), first), rows
    reference = reference_backprojection(
        profiles, positions, grid.pixel_centers(), range_offset_m=RANGE_OFFSET_M, range_bin_m=RANGE_BIN_M,
        center_frequency_hz=CENTER_FREQUENCY_HZ,
    )
    assert _relative_error(images[1], reference) < 1e-4


@pytest.mark.gpu
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
@pytest.mark.filterwarnings("ignore::DeprecationWarning")
@pytest.mark.parametrize("torch_compile", [False, True])
def test_cuda_matches_cpu(busy_scene, torch_compile):
    positions, profiles, grid = busy_scene
    cpu = run(profiles, positions, grid, "numba")
    cuda = backproject(
        torch.from_numpy(profiles).cuda(),
        positions,
        grid,
        range_bin_m=RANGE_BIN_M,
        center_frequency_hz=CENTER_FREQUENCY_HZ,
        range_offset_m=RANGE_OFFSET_M,
        torch_compile=torch_compile,
    )
    assert cuda.device.type == "cuda"
    assert _relative_error(cuda, cpu.astype(np.complex128)) < 1e-4


def _ecef_T_enu(lat_deg: float, lon_deg: float, height_m: float):
    """ENU axes at a geodetic point on the WGS84 ellipsoid, written out independently."""
    lat, lon = np.deg2rad(lat_deg), np.deg2rad(lon_deg)
    a, e2 = 6378137.0, 6.69437999014e-3
    n = a / np.sqrt(1 - e2 * np.sin(lat) ** 2)
    origin = np.array(
        [
            (n + height_m) * np.cos(lat) * np.cos(lon),
            (n + height_m) * np.cos(lat) * np.sin(lon),
            (n * (1 - e2) + height_m) * np.sin(lat),
        ]
    )
    east = [-np.sin(lon), np.cos(lon), 0.0]
    north = [-np.sin(lat) * np.cos(lon), -np.sin(lat) * np.sin(lon), np.cos(lat)]
    up = [np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)]
    return np.column_stack([east, north, up]), origin


@pytest.mark.parametrize("backend", BACKENDS)
def test_focuses_in_ecef(broadside_scene, backend):
    """The same scene written in ECEF (coordinates ~6.4e6 m) forms the same image."""
    positions, target, profiles = broadside_scene
    grid_enu = ImageGrid.axis_aligned(target, [0, 1, 0], [1, 0, 0], 0.04, (32, 40))
    rotation, translation = _ecef_T_enu(37.4, -122.1, 12.0)
    grid_ecef = grid_enu.transformed(rotation, translation)
    positions_ecef = positions @ rotation.T + translation
    assert np.abs(positions_ecef).max() > 4e6

    image_enu = run(profiles, positions, grid_enu, backend)
    image_ecef = run(profiles, positions_ecef, grid_ecef, backend)
    peak = np.unravel_index(np.argmax(np.abs(image_ecef)), image_ecef.shape)
    i, j, _ = grid_ecef.world_to_pixel(target @ rotation.T + translation)
    assert abs(peak[0] - i) <= 1 and abs(peak[1] - j) <= 1
    assert _relative_error(image_ecef, image_enu.astype(np.complex128)) < 1e-4


@pytest.mark.parametrize("backend", BACKENDS)
def test_zero_outside_the_profile(broadside_scene, backend):
    positions, _, profiles = broadside_scene
    beyond_m = RANGE_OFFSET_M + RANGE_BIN_M * NUM_SAMPLES + 1.0
    far = ImageGrid.axis_aligned([0, beyond_m, 0], [0, 1, 0], [1, 0, 0], 0.05, (8, 20))
    near = ImageGrid.axis_aligned([0, 1.0, 0], [0, 1, 0], [1, 0, 0], 0.05, (8, 20))
    assert not np.any(run(profiles, positions, far, backend))
    assert not np.any(run(profiles, positions, near, backend))


def test_output_type_follows_input(broadside_scene):
    positions, target, profiles = broadside_scene
    grid = ImageGrid.axis_aligned(target, [0, 1, 0], [1, 0, 0], 0.04, (4, 4))
    kwargs = dict(range_bin_m=RANGE_BIN_M, center_frequency_hz=CENTER_FREQUENCY_HZ, range_offset_m=RANGE_OFFSET_M)
    as_tensor = backproject(torch.from_numpy(profiles), positions, grid, **kwargs)
    assert isinstance(as_tensor, torch.Tensor) and as_tensor.dtype == torch.complex64
    as_array = backproject(profiles, positions, grid, backend="torch", **kwargs)
    assert isinstance(as_array, np.ndarray)
    np.testing.assert_allclose(as_tensor.numpy(), as_array)


def test_bad_inputs_are_all_reported():
    grid = ImageGrid.axis_aligned([0, 5, 0], [0, 1, 0], [1, 0, 0], 0.04, (4, 4))
    with pytest.raises(ValueError) as info:
        backproject(
            np.zeros((5, 10), np.complex64),
            np.zeros((4, 3)),
            grid,
            range_bin_m=-1.0,
            center_frequency_hz=0.0,
        )
    message = str(info.value)
    assert "4 pulses" in message and "range_bin_m" in message and "center_frequency_hz" in message
    with pytest.raises(ValueError, match="backend"):
        backproject(np.zeros((4, 10), np.complex64), np.zeros((4, 3)), grid, range_bin_m=1.0,
                    center_frequency_hz=1.0, backend="fortran")


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::DeprecationWarning")
def test_torch_compile_matches_reference(busy_scene):
    """The fused (torch.compile) path, which GPUs use for speed, computes the same sum."""
    positions, profiles, grid = busy_scene
    reference = reference_backprojection(
        profiles,
        positions,
        grid.pixel_centers(),
        range_offset_m=RANGE_OFFSET_M,
        range_bin_m=RANGE_BIN_M,
        center_frequency_hz=CENTER_FREQUENCY_HZ,
    )
    image = backproject(
        profiles,
        positions,
        grid,
        range_bin_m=RANGE_BIN_M,
        center_frequency_hz=CENTER_FREQUENCY_HZ,
        range_offset_m=RANGE_OFFSET_M,
        backend="torch",
        torch_compile=True,
    )
    assert _relative_error(image, reference) < 1e-4
