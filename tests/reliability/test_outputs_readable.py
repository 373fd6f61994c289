"""What a user reads: the sync report printed whole, the PR plot's legend off the data."""

from __future__ import annotations

import random

import numpy as np
import pytest

from tests.format.conftest import make_dataset
from zendar_dataset import ZendarDataset
from zendar_dataset.eval import evaluate
from zendar_dataset.eval.render import pr_figure


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    return ZendarDataset(make_dataset(tmp_path_factory.mktemp("report") / "ds", "zarr"), split="train")


def test_printed_sync_report_shows_every_scene_and_stream(dataset):
    report = dataset.sync_report()
    text = str(report)
    lines = text.splitlines()
    assert "rows x" not in text and "..." not in text
    assert len(lines) == len(report) + 3  # header, column names, one line per row, footer
    for scene_id, stream in zip(report["scene_id"], report["stream"]):
        assert any(scene_id in line and stream in line for line in lines), (scene_id, stream)
    # The residual column is the DataFrame's, in milliseconds.
    radar = report[report["stream"] == "radar/left"].iloc[0]
    row = next(line for line in lines if radar["scene_id"] in line and "radar/left" in line)
    assert f"{radar['abs_dt_max_ns'] / 1e6:.3f}" in row.split()


def test_sync_report_is_still_the_whole_dataframe(dataset):
    report = dataset.sync_report()
    assert len(report.columns) == 16 and {"dt_mean_ns", "abs_dt_p95_ns", "window"} <= set(report.columns)
    indexed = report.set_index(["scene_id", "stream"])
    assert indexed.loc[(dataset.scene_ids[0], "radar/left"), "items"] == report["items"].iloc[0]
    assert "dt_mean_ns" in report.to_string()


def _metrics():
    # Far-band detections whose first ranks are false positives: precision near 0 at low recall,
    # exactly where a lower-left legend used to sit.
    rng = random.Random(7)
    frames, results = {}, {}
    for k in range(40):
        frame = f"s/{k}"
        cars = [{"x": rng.uniform(31, 55), "y": rng.uniform(-5, 5)} for _ in range(3)]
        frames[frame] = cars
        results[frame] = [{"x": c["x"], "y": c["y"], "score": rng.uniform(0.0, 0.9)} for c in cars[:2]]
        results[frame] += [{"x": 45.0, "y": 40.0, "score": rng.uniform(0.8, 1.0)}]
    return evaluate({"results": results}, {"frames": frames})


@pytest.mark.parametrize("band", ["far", "all"])
def test_pr_legend_does_not_cover_the_plot(band):
    metrics = _metrics()
    figure = pr_figure(metrics, band)
    figure.canvas.draw()
    axes = figure.axes[0]
    legend = axes.get_legend()
    axes_box = axes.get_window_extent()
    legend_box = legend.get_window_extent()
    assert legend_box.y1 <= axes_box.y0 + 1e-6, (legend_box, axes_box)  # entirely below the axes
    figure_box = figure.bbox
    assert figure_box.x0 <= legend_box.x0 and legend_box.x1 <= figure_box.x1 and legend_box.y0 >= figure_box.y0
    assert np.isfinite(metrics["ap"][band])
