"""The bird's-eye figure composes the radars' SAR images per cell: the overlap shows both."""

from __future__ import annotations

import numpy as np

from zendar_baselines.bench.figures import bev_figure, compose_layers


def _layer(x0: float, y0: float, n: int, value: float, angle_rad: float = 0.0, spacing_m: float = 0.5):
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    u, v = i * spacing_m, j * spacing_m
    xy = np.stack([x0 + c * u - s * v, y0 + s * u + c * v], axis=-1)
    return np.full((n, n), value), xy


def test_the_overlap_keeps_the_brighter_radar_whatever_the_order():
    left = _layer(10.0, -5.0, 20, 3.0)       # x 10..19.5, y -5..4.5
    right = _layer(10.0, 0.0, 20, 1.0)       # x 10..19.5, y 0..9.5
    left[0][4, 12] = 25.0                    # a bright scatterer at x 12, y 1, inside the overlap
    right[0][4, 2] = -4.0                    # the other radar sees it dark there
    grid, cell = compose_layers([left, right], extent_m=30.0, cell_m=0.5)
    again, _ = compose_layers([right, left], extent_m=30.0, cell_m=0.5)
    np.testing.assert_array_equal(np.nan_to_num(grid, nan=-99), np.nan_to_num(again, nan=-99))

    def at(x: float, y: float) -> float:
        return grid[int(np.floor((x + 30.0) / cell)), int(np.floor((y + 30.0) / cell))]

    assert at(12.0, 1.0) == 25.0             # drawn one over the other, the right radar's -4 would hide it
    assert at(15.0, -3.0) == 3.0             # only the left radar
    assert at(15.0, 8.0) == 1.0              # only the right radar
    assert at(15.0, 2.0) == 3.0              # the overlap: the brighter of the two
    assert np.isnan(at(-20.0, 0.0))          # no image


def test_a_rotated_image_leaves_no_hole_inside_it():
    layer = _layer(20.0, 0.0, 40, 5.0, angle_rad=np.radians(37.0), spacing_m=0.4)
    grid, cell = compose_layers([layer], extent_m=40.0)
    assert cell >= 0.4
    # Cells well inside the rotated square (its centre +- 4 m) are all covered.
    centre = layer[1][20, 20]
    i0, j0 = np.floor((centre + 40.0) / cell).astype(int)
    half = int(4.0 / cell)
    assert np.all(np.isfinite(grid[i0 - half:i0 + half, j0 - half:j0 + half]))


def test_the_figure_draws_one_composed_image():
    figure = bev_figure([_layer(10.0, -5.0, 20, 3.0), _layer(10.0, 0.0, 20, 1.0)], [], {"m": []}, "t")
    assert len(figure.axes[0].images) == 1
