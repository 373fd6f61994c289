"""The bird's-eye figure composes the radars' SAR images per cell: the overlap shows both; the training
curves draw every phase of every row, one panel per architecture."""

from __future__ import annotations

import json

import numpy as np
import pytest

from zendar_dataset.errors import ZendarError

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


def _curves(row: str, seed: int, phases: list[tuple[str, list[float], list[float], int]]) -> dict:
    return {"format": "zendar-bench-curves", "format_version": 1, "row": row, "seed": seed, "validation": "val split",
            "phases": [{"phase": name, "best_epoch": best,
                        "epochs": [{"epoch": e, "train": t, "validation": v} for e, (t, v) in enumerate(zip(train, val), 1)]}
                       for name, train, val, best in phases]}


def test_the_curves_figure_has_a_panel_per_architecture_and_marks_the_epochs_chosen(tmp_path):
    from zendar_baselines.bench.figures import loss_curves_figure, write_loss_curves

    supervised = _curves("densenet-37-supervised", 0, [("supervised", [0.5, 0.3, 0.2], [0.6, 0.4, 0.45], 2)])
    pretrained = _curves("densenet-37-pretrained", 0, [("pretrain", [0.4, 0.3], [0.5, 0.35], 2),
                                                        ("fine-tune", [0.25, 0.2, None], [0.3, 0.28, 0.29], 2)])
    other = _curves("fpn-resnet34-supervised", 1, [("supervised", [0.5, 0.4], [0.5, 0.45], 2)])
    figure = loss_curves_figure([supervised, pretrained, other])
    panels = [axes for axes in figure.axes if axes.get_title()]
    assert [axes.get_title() for axes in panels] == ["densenet-37", "fpn-resnet34"]
    stars = {tuple(np.round(line.get_xydata()[0], 6)) for line in panels[0].lines if line.get_marker() == "*"}
    # The fine-tuning epochs follow the 2 pretraining epochs: its chosen epoch 2 is drawn at 4.
    assert stars == {(2.0, 0.4), (2.0, 0.35), (4.0, 0.28)}
    dashed = [line for line in panels[0].lines if line.get_linestyle() == "--"]
    assert sorted(list(line.get_xdata()) for line in dashed) == [[1, 2], [1, 2, 3], [3, 4, 5]]

    rows = tmp_path / "rows"
    for record in (supervised, pretrained, other):
        seed_dir = rows / record["row"] / f"seed-{record['seed']}"
        seed_dir.mkdir(parents=True)
        (seed_dir / "curves.json").write_text(json.dumps(record))
    path = write_loss_curves(tmp_path / "curves.png", sorted(rows.iterdir()))
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and path.stat().st_size > 10_000
    assert write_loss_curves(tmp_path / "none.png", []) is None and not (tmp_path / "none.png").exists()
    (rows / "empty-supervised").mkdir()
    with pytest.raises(ZendarError, match="empty-supervised: no seed-"):
        write_loss_curves(tmp_path / "curves.png", [rows / "empty-supervised"])
