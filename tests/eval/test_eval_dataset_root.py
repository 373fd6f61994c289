"""``--gt DATASET_ROOT``: labels read through the format's ground-truth export."""

import json

import numpy as np
import pytest

from zendar_dataset.cli.eval import main
from zendar_dataset.eval import evaluate
from zendar_dataset.format.writer import DatasetWriter

T0_NS = 1_600_000_000_000_000_000
FRAME_NS = 100_000_000
ENU_ORIGIN = {"lat_deg": 37.7749, "lon_deg": -122.4194, "height_m": 12.5}
CALIBRATION = {
    "sensors": {
        "left": {
            "rotation_wxyz": [1.0, 0.0, 0.0, 0.0],
            "translation_m": [0.0, 0.0, 0.5],
            "center_frequency_hz": 77e9,
            "bandwidth_hz": 833e6,
            "range_bin_m": 0.18,
            "doppler_bin_mps": 0.1,
            "rx_positions_m": [[0.0, 0.0019 * a, 0.0] for a in range(4)],
        },
        "imu": {"rotation_wxyz": [0.0, 1.0, 0.0, 0.0], "translation_m": [-2.0, 0.0, 0.3]},
    }
}


def write_scene(writer, cars_per_frame, *, labels=True):
    """Two SAR frames; frame k holds the cars ``cars_per_frame[k]`` as (x, y)."""
    for k in range(len(cars_per_frame)):
        t = T0_NS + k * FRAME_NS
        image = np.zeros((4, 4), dtype=np.complex64)
        origin = np.array([-2_700_000.0, -4_290_000.0, 3_850_000.0])
        writer.append_sar("left", t, image, origin, [0.1, 0.0, 0.0], [0.0, 0.1, 0.0], [t - 50_000_000, t + 50_000_000])
    k = np.arange(40)
    position = np.array([-2_700_000.0, -4_290_000.0, 3_850_000.0]) + np.outer(k, [0.1, 0.2, 0.0])
    writer.write_tracklog(T0_NS - FRAME_NS + k * 10_000_000, position, np.tile([1.0, 0.0, 0.0, 0.0], (40, 1)))
    if labels:
        rows = [(T0_NS + k * FRAME_NS, x, y) for k, cars in enumerate(cars_per_frame) for x, y in cars]
        n = len(rows)
        writer.write_labels(
            {
                "timestamp_ns": np.array([r[0] for r in rows], dtype=np.int64),
                "x": np.array([r[1] for r in rows], dtype=np.float64),
                "y": np.array([r[2] for r in rows], dtype=np.float64),
                "length": np.full(n, 4.5),
                "width": np.full(n, 1.8),
                "yaw": np.zeros(n),
                "vx": np.zeros(n),
                "vy": np.zeros(n),
                "track_id": np.arange(n, dtype=np.int64),
            }
        )


def make_dataset(root, *, test_labelled):
    writer = DatasetWriter(root, "tiny-eval")
    layout = {"v0": ([[(5.0, 0.0)], []], True), "t0": ([[(20.0, 1.0), (40.0, -3.0)], [(7.0, 7.0)]], test_labelled)}
    for scene_id, (cars, labels) in layout.items():
        with writer.scene(scene_id, enu_origin=ENU_ORIGIN, calibration=CALIBRATION) as scene:
            write_scene(scene, cars, labels=labels)
    writer.finalize({"val": ["v0"], "test": ["t0"]})
    return root


def frame(scene, k):
    return f"{scene}/{T0_NS + k * FRAME_NS}"


def test_default_split_is_test_when_labelled(tmp_path):
    root = make_dataset(tmp_path / "ds", test_labelled=True)
    predictions = {
        "meta": {"method": "m"},
        "results": {
            frame("t0", 0): [{"x": 21.0, "y": 1.0, "score": 0.9}, {"x": 40.0, "y": -1.0, "score": 0.8}],
            frame("t0", 1): [],
        },
    }
    metrics = evaluate(predictions, root)
    assert metrics["split"] == "test"
    assert metrics["counts"]["mid"] == {"gt": 1, "tp": 1, "fp": 0}
    assert metrics["counts"]["far"] == {"gt": 1, "tp": 1, "fp": 0}
    assert metrics["counts"]["near"] == {"gt": 1, "tp": 0, "fp": 0}
    assert metrics["ap"] == {"near": 0.0, "mid": 1.0, "far": 1.0, "all": pytest.approx(2 / 3)}


def test_default_split_falls_back_to_val_and_cli_says_so(tmp_path, capsys):
    root = make_dataset(tmp_path / "ds", test_labelled=False)
    path = tmp_path / "p.json"
    path.write_text(json.dumps({"results": {frame("v0", 0): [{"x": 5.5, "y": 0.0, "score": 0.3}], frame("v0", 1): []}}))
    out = tmp_path / "out"
    assert main([str(path), "--gt", str(root), "--out", str(out)]) == 0
    assert "split: val" in capsys.readouterr().out
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["split"] == "val" and metrics["ap"]["near"] == 1.0
    # Asking for the withheld split explicitly is an error that says why.
    assert main([str(path), "--gt", str(root), "--split", "test"]) == 2
    assert "split 'test'" in capsys.readouterr().err
