"""Table 1 from scored rows: means and standard deviations by hand, the paper's figures (claims: test_claims.py)."""

from __future__ import annotations

import csv
import io
import math

import numpy as np

from zendar_baselines.bench.figures import bev_figure, pr_comparison_figure
from zendar_baselines.bench.results_table import Row, csv_table, markdown_table
from zendar_dataset.eval import MetricsRecord


def _metrics(near, mid, far, all_=None):
    ap = {"near": near, "mid": mid, "far": far, "all": all_ if all_ is not None else near}
    curve = {"recall": [0.5, 1.0], "precision": [1.0, 0.5], "precision_envelope": [1.0, 0.5], "score": [2.0, 1.0]}
    return MetricsRecord.from_json({
        "ap": ap, "counts": {b: {"gt": 2, "tp": 2, "fp": 1} for b in ap}, "pr_curves": {b: curve for b in ap},
        "protocol": {}, "partial": False, "n_frames": 1, "n_frames_ground_truth": 1, "n_scenes": 1,
        "n_predictions": 3, "meta": {},
    })


def _rows():
    return [
        Row("cfar", "CFAR", False, False, [_metrics(0.5, 0.4, 0.2)]),
        Row("densenet-37-supervised", "zoom-out DenseNet-37", False, True,
            [_metrics(0.6, 0.5, 0.3), _metrics(0.8, 0.5, 0.1)]),
        Row("densenet-37-pretrained", "zoom-out DenseNet-37", True, True,
            [_metrics(0.9, 0.6, 0.4), _metrics(0.7, 0.6, 0.2)]),
    ]


def test_mean_and_sample_std_over_seeds():
    row = _rows()[1]
    assert math.isclose(row.ap_mean()["near"], 0.7)
    assert math.isclose(row.ap_std()["near"], math.sqrt(((0.6 - 0.7) ** 2 + (0.8 - 0.7) ** 2) / 1))
    entry = row.to_json()
    assert entry["ap"]["far"] == 0.2 and entry["n_seeds"] == 2 and entry["ap_std"]["mid"] == 0.0
    assert entry["paper_ap"] == {"near": 0.67, "mid": 0.598, "far": 0.283}
    assert _rows()[0].to_json().get("ap_std") is None  # one seed: no spread claimed


def test_markdown_and_csv_carry_ours_and_the_papers():
    text = markdown_table(_rows(), "tiny")
    assert "| zoom-out DenseNet-37 | ✓ | ✓ | 80.0 ± 14.1 | 60.0 ± 0.0 | 30.0 ± 14.1 |" in text
    assert "| CFAR | - | - | 50.0 | 40.0 | 20.0 | 50.0 | 65.0 | 43.0 | 13.3 |" in text
    rows = list(csv.DictReader(io.StringIO(csv_table(_rows()))))
    assert rows[0]["method"] == "CFAR" and rows[0]["ap_near"] == "0.5000" and rows[0]["paper_ap_far"] == "0.133"
    assert rows[2]["ap_far_std"] == f"{math.sqrt(0.02):.4f}"


def test_figures_draw_every_method():
    figure = pr_comparison_figure([(row.method, row.seed_metrics[0]) for row in _rows()], "near")
    assert len(figure.axes[0].get_legend().get_texts()) == 3
    xy = np.stack(np.meshgrid(np.arange(0, 40.0), np.arange(-20, 20.0), indexing="ij"), axis=-1)
    bev = bev_figure([(np.zeros(xy.shape[:2]), xy)], [{"x": 10, "y": 2, "length": 4.5, "width": 1.8, "yaw": 0.3}],
                     {"CFAR": [{"x": 10.5, "y": 2.0, "score": 1.0}], "DenseNet": []}, "frame")
    labels = [t.get_text() for t in bev.axes[0].get_legend().get_texts()]
    assert labels == ["ground truth", "CFAR", "DenseNet (none)", "ego"]



