"""ImageGrid: pixel/world round trips, construction helpers, frame changes, validation."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from zendar_dataset.errors import ZendarFormatError
from zendar_dataset.geometry.se3 import SE3
from zendar_dataset.sar import ImageGrid


@pytest.fixture
def skewed_grid() -> ImageGrid:
    # Non-orthogonal, unequal steps, in ECEF-sized coordinates.
    return ImageGrid(
        origin=[-2.7e6, -4.3e6, 3.85e6], di=[0.04, 0.01, 0.0], dj=[0.005, 0.03, 0.02], shape=(30, 50)
    )


def test_pixel_world_round_trip(skewed_grid):
    rng = np.random.default_rng(0)
    i = rng.uniform(-5, 35, 200)
    j = rng.uniform(-5, 55, 200)
    height_m = rng.uniform(-2, 2, 200)
    points = skewed_grid.pixel_to_world(i, j) + height_m[:, None] * skewed_grid.normal
    i_back, j_back, out_of_plane_m = skewed_grid.world_to_pixel(points)
    np.testing.assert_allclose(i_back, i, atol=1e-6)
    np.testing.assert_allclose(j_back, j, atol=1e-6)
    np.testing.assert_allclose(out_of_plane_m, height_m, atol=1e-6)


def test_pixel_centers_follow_the_image_model(skewed_grid):
    centers = skewed_grid.pixel_centers()
    assert centers.shape == (30, 50, 3)
    np.testing.assert_allclose(centers[0, 0], skewed_grid.origin)
    np.testing.assert_allclose(centers[7, 11], skewed_grid.origin + 7 * skewed_grid.di + 11 * skewed_grid.dj)


def test_axis_aligned_is_centred_and_square():
    grid = ImageGrid.axis_aligned([10.0, 20.0, 1.0], u=[1, 0, 0], v=[0.2, 1, 0], pixel_m=0.04, shape=(40, 31))
    np.testing.assert_allclose(grid.center, [10.0, 20.0, 1.0])
    np.testing.assert_allclose(np.linalg.norm(grid.di), 0.04)
    np.testing.assert_allclose(np.linalg.norm(grid.dj), 0.04)
    assert abs(grid.di @ grid.dj) < 1e-15
    np.testing.assert_allclose(grid.normal, [0, 0, 1])
    # Odd side: the centre is a pixel.
    i, j, _ = grid.world_to_pixel([10.0, 20.0, 1.0])
    assert (i, j) == pytest.approx((19.5, 15.0))


def test_transformed_moves_every_pixel():
    grid = ImageGrid.axis_aligned([3.0, -4.0, 0.5], [1, 1, 0], [-1, 1, 0], 0.1, (6, 9))
    rotation = Rotation.from_euler("zyx", [30, -10, 5], degrees=True)
    translation = np.array([-2.7e6, -4.3e6, 3.85e6])
    expected = grid.pixel_centers() @ rotation.as_matrix().T + translation
    for moved in (grid.transformed(rotation, translation), grid.transformed(SE3(rotation.as_matrix(), translation))):
        np.testing.assert_allclose(moved.pixel_centers(), expected, atol=1e-8, rtol=0)
        assert moved.shape == grid.shape


def test_invalid_grid_lists_every_problem():
    with pytest.raises(ZendarFormatError) as info:
        ImageGrid(origin=[0, 0], di=[1, 0, 0], dj=[2, 0, 0], shape=(0, 3))
    problems = info.value.problems
    assert any("origin" in p for p in problems)
    assert any("shape" in p for p in problems)
    assert any("parallel" in p for p in problems)
    with pytest.raises(ZendarFormatError, match="non-zero"):
        ImageGrid(origin=[0, 0, 0], di=[0, 0, 0], dj=[0, 1, 0], shape=(2, 2))
    with pytest.raises(ZendarFormatError, match="finite"):
        ImageGrid(origin=[np.nan, 0, 0], di=[1, 0, 0], dj=[0, 1, 0], shape=(2, 2))


def test_grid_is_immutable():
    grid = ImageGrid(origin=[0, 0, 0], di=[1, 0, 0], dj=[0, 1, 0], shape=(2, 2))
    with pytest.raises(ValueError):
        grid.origin[0] = 5.0
