"""The real ``zendar-eval`` command: exit statuses, printed problems, outputs."""

import json
import os
import random
import shutil
import subprocess
import sys

import pytest

from zendar_dataset.cli.eval import main
from zendar_dataset.eval import evaluate
from zendar_dataset.eval.report import format_table

ZENDAR_EVAL = shutil.which("zendar-eval")


def run_cli(*args, cwd=None):
    command = [ZENDAR_EVAL] if ZENDAR_EVAL else [sys.executable, "-m", "zendar_dataset.cli.eval"]
    return subprocess.run(command + [str(a) for a in args], capture_output=True, text=True, cwd=cwd, timeout=120)


def scenes_data(n_scenes=8, frames_per_scene=6, seed=3):
    rng = random.Random(seed)
    frames, results = {}, {}
    for s in range(n_scenes):
        for t in range(frames_per_scene):
            frame_id = f"scene-{s:02d}/{1_000_000 * t}"
            cars = [{"x": rng.uniform(-55, 55), "y": rng.uniform(-55, 55)} for _ in range(rng.randint(0, 5))]
            frames[frame_id] = cars
            results[frame_id] = [
                {"x": c["x"] + rng.gauss(0, 1.2), "y": c["y"] + rng.gauss(0, 1.2), "score": rng.random()}
                for c in cars
                if rng.random() < 0.8
            ] + [{"x": rng.uniform(-55, 55), "y": rng.uniform(-55, 55), "score": rng.random() * 0.6}]
    return {"frames": frames, "split": "test"}, {"meta": {"method": "noisy-oracle"}, "results": results}


@pytest.fixture
def files(tmp_path):
    ground_truth, predictions = scenes_data()
    gt_path = tmp_path / "gt.json"
    pred_path = tmp_path / "pred.json"
    gt_path.write_text(json.dumps(ground_truth))
    pred_path.write_text(json.dumps(predictions))
    return gt_path, pred_path, ground_truth, predictions


def test_every_bad_input_is_listed_and_exits_2(tmp_path, files):
    gt_path, _, ground_truth, _ = files
    frame_ids = list(ground_truth["frames"])
    results = {f: [] for f in frame_ids[2:]}  # frames 0 and 1 missing
    results[frame_ids[2]] = [
        {"x": 1.0, "y": 2.0},
        "not an object",
        {"x": True, "y": 2.0, "score": 0.5},
        {"x": 1.0, "y": 2.0, "score": "high"},
    ]
    results[frame_ids[3]] = [{"x": 1.0, "y": 2.0, "score": 0.1}] * 501
    results["elsewhere/5"] = []
    text = json.dumps({"meta": {"method": "m"}, "results": results})
    # Non-finite literals, as Python's json writes them.
    text = text.replace(json.dumps(frame_ids[4]) + ": []", json.dumps(frame_ids[4]) + ': [{"x": NaN, "y": Infinity, "score": 1}]')
    bad = tmp_path / "bad.json"
    bad.write_text(text)
    completed = run_cli(bad, "--gt", gt_path)
    assert completed.returncode == 2
    assert "Traceback" not in completed.stderr
    expected = [
        f"frame {frame_ids[0]!r} is missing from predictions",
        f"frame {frame_ids[1]!r} is missing from predictions",
        f"frame {frame_ids[2]!r} detection 0: missing 'score'",
        f"frame {frame_ids[2]!r} detection 1: expected an object",
        f"frame {frame_ids[2]!r} detection 2: 'x' must be a number, got bool",
        f"frame {frame_ids[2]!r} detection 3: 'score' must be a number, got str",
        f"frame {frame_ids[3]!r}: 501 detections, more than the limit of 500",
        f"frame {frame_ids[4]!r} detection 0: 'x' is not finite (nan)",
        f"frame {frame_ids[4]!r} detection 0: 'y' is not finite (inf)",
        "frame 'elsewhere/5' is not in the ground truth",
    ]
    assert f"error: {len(expected)} problems found:" in completed.stderr
    for line in expected:
        assert line in completed.stderr, line


@pytest.mark.parametrize(
    ("content", "extra_args", "expected"),
    [
        ("[1, 2", [], "is not valid JSON"),
        ("[]", [], "expected a JSON object"),
        ('{"meta": {}}', [], "missing 'results'"),
        ('{"results": 5}', [], "'results' must be an object"),
        ('{"results": {}}', ["--max-bytes", "3"], "over the limit of 3 bytes"),
    ],
)
def test_bad_files_exit_2_in_process(tmp_path, files, capsys, content, extra_args, expected):
    gt_path = files[0]
    path = tmp_path / "p.json"
    path.write_text(content)
    assert main([str(path), "--gt", str(gt_path), *extra_args]) == 2
    assert expected in capsys.readouterr().err


def test_bad_ground_truth_file_exits_2(tmp_path, files):
    _, pred_path, _, _ = files
    gt_path = tmp_path / "gt_bad.json"
    gt_path.write_text('{"frames": {"a/1": [{"x": 1.0, "y": NaN}], "a/2": [{"y": 3}]}}')
    completed = run_cli(pred_path, "--gt", gt_path)
    assert completed.returncode == 2
    assert "ground truth frame 'a/1' detection 0: 'y' is not finite (nan)" in completed.stderr
    assert "ground truth frame 'a/2' detection 0: missing 'x'" in completed.stderr


def test_table_metrics_json_plots_and_bootstrap(tmp_path, files):
    gt_path, pred_path, ground_truth, predictions = files
    out = tmp_path / "out" / "nested"
    completed = run_cli(pred_path, "--gt", gt_path, "--out", out, "--plot", "--bootstrap", "200", cwd=tmp_path)
    assert completed.returncode == 0, completed.stderr
    metrics = json.loads((out / "metrics.json").read_text())
    expected = evaluate(predictions, ground_truth, bootstrap=200)
    assert metrics == json.loads(json.dumps(expected))
    assert metrics["split"] == "test"
    assert metrics["meta"] == {"method": "noisy-oracle"}
    # The table prints AP in percent with one decimal, like the paper's Table 1.
    near = metrics["ap"]["near"]
    row = next(line for line in completed.stdout.splitlines() if line.startswith("near "))
    assert f"{100 * near:.1f}" in row
    assert "split: test" in completed.stdout
    for band in ("near", "mid", "far", "all"):
        png = out / f"pr_{band}.png"
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        interval = metrics["bootstrap"][band]
        assert interval["n"] > 150
        assert interval["low"] <= metrics["ap"][band] <= interval["high"]
        assert interval["low"] < interval["high"]
    assert not [p for p in os.listdir(out) if p.startswith(".")]  # no temporary files left


def test_rerun_overwrites_its_own_metrics(tmp_path, files):
    gt_path, pred_path, _, _ = files
    out = tmp_path / "out"
    assert main([str(pred_path), "--gt", str(gt_path), "--out", str(out)]) == 0
    (out / "metrics.json").write_text("old")
    assert main([str(pred_path), "--gt", str(gt_path), "--out", str(out)]) == 0
    assert json.loads((out / "metrics.json").read_text())["n_frames"] == 48
    not_a_dir = tmp_path / "file"
    not_a_dir.write_text("mine")
    assert main([str(pred_path), "--gt", str(gt_path), "--out", str(not_a_dir)]) == 1  # environment, not input
    assert not_a_dir.read_text() == "mine"


def test_partial_is_announced(tmp_path, files, capsys):
    gt_path, _, _, predictions = files
    subset = dict(list(predictions["results"].items())[:10])
    path = tmp_path / "subset.json"
    path.write_text(json.dumps({"meta": predictions["meta"], "results": subset}))
    out = tmp_path / "o"
    assert main([str(path), "--gt", str(gt_path), "--partial", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "PARTIAL evaluation: 10 of 48 ground-truth frames" in printed
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["partial"] is True and metrics["n_frames"] == 10
    assert main([str(path), "--gt", str(gt_path)]) == 2  # without --partial: 38 missing frames


def test_bootstrap_is_deterministic_and_seeded(files):
    _, _, ground_truth, predictions = files
    first = evaluate(predictions, ground_truth, bootstrap=50, seed=1)["bootstrap"]
    assert evaluate(predictions, ground_truth, bootstrap=50, seed=1)["bootstrap"] == first
    assert evaluate(predictions, ground_truth, bootstrap=50, seed=2)["bootstrap"] != first


def test_bootstrap_of_one_scene_is_the_point_estimate(files):
    _, _, ground_truth, predictions = files
    frames = {f: v for f, v in ground_truth["frames"].items() if f.startswith("scene-00/")}
    results = {f: predictions["results"][f] for f in frames}
    metrics = evaluate({"results": results}, {"frames": frames}, bootstrap=20)
    for band, interval in metrics["bootstrap"].items():
        if metrics["ap"][band] is None:
            assert interval == {"low": None, "high": None, "n": 0}
        else:
            assert interval["low"] == pytest.approx(metrics["ap"][band])
            assert interval["high"] == pytest.approx(metrics["ap"][band])
    assert "one scene: resampling scenes cannot show scene-to-scene spread" in format_table(metrics)
    several = evaluate(predictions, ground_truth, bootstrap=20)
    assert "one scene" not in format_table(several)


def test_plot_needs_out(files):
    gt_path, pred_path, _, _ = files
    with pytest.raises(SystemExit) as info:
        main([str(pred_path), "--gt", str(gt_path), "--plot"])
    assert info.value.code == 2

