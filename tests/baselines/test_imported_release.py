"""``zendar-bench`` on an imported release, which has no manual labels: automatic labels with their
statistics, the CFAR predictions as a leaderboard submission and pretraining run; every row and step
that needs manual labels is listed as skipped with the reason."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from tests.release import fixture as fx
from tests.release.sdk_messages import sdk, write_recording
from zendar_dataset.format import open_dataset
from zendar_dataset.sync import resolve_reference

pytestmark = pytest.mark.slow  # trains a CNN (about 20 s on 2 cores)

R, D, A = 64, 32, 4  # the tiny profile's cube: the CFAR window and the CNNs need that much
TIMES_S = np.arange(0.0, 1.2, 0.1)


def _vec(vec, xyz) -> None:
    vec.x, vec.y, vec.z = (float(v) for v in xyz)


def _quat(quat, wxyz) -> None:
    quat.w, quat.x, quat.y, quat.z = (float(v) for v in wxyz)


def write_release(scene, cube_shape=(R, D, A)) -> None:
    """One 1.2 s scene written with the SDK's 2020 definitions: both radars' SAR images and detections,
    the tracklog and, unless ``cube_shape`` is None, the left radar's range-Doppler cubes of that shape
    (noise and, in the tiny profile's, one approaching target)."""
    m = sdk("2020")
    rng = np.random.default_rng(5)
    for serial, side in fx.SERIALS.items():
        images, states = [], []
        for k, t in enumerate(TIMES_S):
            frame = fx.sar_frame(side, float(t), k)
            p_enu, R_ecef_imu, _ = fx.vehicle(float(t))
            image = m["Image"](timestamp=frame.timestamp_s, frame_id=k)
            _quat(image.attitude, fx.wxyz(R_ecef_imu))
            _vec(image.position, fx.enu_to_ecef(p_enu))
            for name in ("origin", "di", "dj"):
                _vec(getattr(image.cartesian.model, name), getattr(frame, f"{name}_ecef"))
            pixels = image.cartesian.data
            pixels.type, pixels.rows, pixels.cols = pixels.REAL_32U, fx.ROWS, fx.COLS
            pixels.data = fx.magnitude_buffer(*frame.bright_ij, rng)
            images.append(image)
            state = m["TrackerState"](frame_id=k)
            state.timestamp.common = frame.timestamp_s
            point = state.detection.add(range=10.0, azimuth=0.1, elevation=0.0, range_velocity=-3.0, amplitude=40.0)
            point.timestamp.common = frame.timestamp_s
            _vec(point.position, frame.target_ecef)
            states.append(state)
        write_recording(scene / f"{serial}_images.pbs", images)
        write_recording(scene / f"{serial}_points.pbs", states)
    poses = []
    for k, t in enumerate(np.arange(-0.2, 1.4, 0.02)):
        p_enu, R_ecef_imu, _ = fx.vehicle(float(t))
        pose = m["Position"](timestamp=fx.T0_S + float(t), update_id=k)
        _quat(pose.attitude, fx.wxyz(R_ecef_imu))
        _vec(pose.position, fx.enu_to_ecef(p_enu))
        poses.append(pose)
    write_recording(scene / "vn200.pbs", poses)
    if cube_shape is not None:
        _write_cubes(scene, m, rng, cube_shape)


def _write_cubes(scene, m, rng, shape) -> None:
    n_range, n_doppler, n_rx = shape
    wavelength = 0.0039
    model = m["RangeDopplerImageModel"](num_rx=n_rx, wavelength=wavelength)
    model.range_axis_params.start, model.range_axis_params.delta, model.range_axis_params.count = 0.0, 0.6, n_range
    model.doppler_axis_params.start, model.doppler_axis_params.delta = -n_doppler / 2 * 1.25, 1.25
    model.doppler_axis_params.count = n_doppler
    for a in range(n_rx):
        _vec(model.rx_positions.add(), (a * wavelength / 2, 0.0, 0.0))  # the release's radar frame: x left
    write_recording(scene / "range_Doppler" / "left_model.pbs", [model])
    frames = []
    for t in TIMES_S:
        cube = (rng.normal(size=shape) + 1j * rng.normal(size=shape)).astype("<c8")
        if shape == (R, D, A):
            cube[17, 8, :] += 300.0  # 10.2 m straight out (azimuth 0), inside the SAR image; -10 m/s
        frames.append(m["RangeDopplerFrame"](timestamp=fx.T0_S + float(t) - 0.01, data=cube.tobytes()))
    write_recording(scene / "range_Doppler" / "left_rd.pbs", frames)


@pytest.fixture(scope="module")
def imported(tmp_path_factory):
    """The recording imported twice into one dataset: once as a training scene, once as a test scene."""
    from zendar_dataset.cli.data import main

    root = tmp_path_factory.mktemp("imported")
    write_release(root / "release" / "2020-02-03_2252" / "001")
    for scene_id, split in (("drive-train", "train"), ("drive-test", "test")):
        status = main(["import-release", str(root / "release"), str(root / "data"), "--scene-id", scene_id, "--split", split])
        assert status == 0
    return root / "data"


@pytest.fixture(scope="module")
def label_free_run(imported, tmp_path_factory, one_thread):
    from zendar_baselines.bench.configs import Schedule, get_config
    from zendar_baselines.bench.run import BenchOptions, run_bench

    # --quick's config, one CNN and a short pretraining: the steps are the same, only shorter.
    config = replace(get_config("tiny"), models=("fpn-resnet34",), pretrain=Schedule(lr=1e-3, batch_size=4, epochs=2))
    out = tmp_path_factory.mktemp("bench") / "out"
    results = run_bench(BenchOptions(config=config, data=imported, out=out, seeds=1, device="cpu", jobs=1))
    return imported, out, results


def test_rows_that_need_manual_labels_are_skipped_with_the_reason(label_free_run):
    _, out, results = label_free_run
    assert results == json.loads((out / "results.json").read_text())
    assert results["manual_labels"] is False
    rows = {row["key"]: row for row in results["rows"]}
    assert list(rows) == ["cfar", "fpn-resnet34-supervised", "fpn-resnet34-pretrained"]
    assert rows["cfar"]["skipped"] == "scoring" and rows["cfar"]["done"] == "predictions of the 12 test frames"
    assert rows["fpn-resnet34-supervised"]["done"] is None and rows["fpn-resnet34-supervised"]["skipped"] == "training and scoring"
    assert rows["fpn-resnet34-pretrained"]["skipped"] == "fine-tuning and scoring"
    assert all("no manual labels" in row["reason"] for row in rows.values())
    assert results["claims"]["skipped"] is True and "no manual labels" in results["claims"]["reason"]
    assert {entry["what"] for entry in results["skipped"]} >= {"fpn-resnet34-supervised: training and scoring",
                                                               "the paper's claims"}
    table = (out / "table.md").read_text()
    assert "| CFAR | predictions of the 12 test frames (rows/cfar/predictions.json) | scoring | the dataset has no manual labels |" in table
    assert "| FPN ResNet-34 supervised-only | - | training and scoring |" in table
    assert "| the paper's claims | - | all |" in table
    assert not (out / "rows" / "cfar" / "metrics.json").exists()


def test_cfar_predictions_are_a_submission_of_every_test_frame(label_free_run):
    from zendar_dataset.eval.validation import read_predictions
    from zendar_leaderboard.meta import meta_problems

    data, out, _ = label_free_run
    predictions = json.loads((out / "rows" / "cfar" / "predictions.json").read_text())
    assert read_predictions(predictions).problems == []
    with open_dataset(data).open_scene("drive-test") as reader:
        frames = reader.timestamps(resolve_reference(reader, "sar"))
    assert sorted(predictions["results"]) == sorted(f"drive-test/{int(t)}" for t in frames)
    assert any(predictions["results"].values())  # the target, found
    meta = predictions["meta"]
    assert meta["chain_fit"] == {"fitted": False, "reason": "the dataset has no manual labels"}
    assert "team" not in meta and "contact" not in meta  # the submitter's, not the bench's
    assert meta_problems({**meta, "team": "Radar Lab", "contact": "lead@example.org"}) == []


def test_automatic_labels_statistics_and_pretraining(label_free_run):
    from zendar_baselines.labels.mask_classes import MOVING
    from zendar_baselines.labels.mask_store import MaskStore

    data, out, results = label_free_run
    statistics = results["autolabel_statistics"]
    assert list(statistics["scenes"]) == ["drive-train"]  # the training split only
    counts = statistics["scenes"]["drive-train"]["left"]
    assert counts["cubes"] == len(TIMES_S) and counts["cells"] == len(TIMES_S) * R * D
    _, masks = MaskStore.open(out / "autolabels" / "store", open_dataset(data)).scene("drive-train")["left"]
    moving = masks == MOVING
    assert counts["moving_cells"] == int(moving.sum()) > 0  # the target where the SAR image is dark
    assert counts["cubes_with_moving"] == int(moving.any(axis=(1, 2)).sum())
    assert statistics["all"] == counts
    assert "### Automatic labels of the training split" in (out / "table.md").read_text()
    record = json.loads((out / "rows" / "fpn-resnet34-pretrained" / "seed-0" / "checkpoint.json").read_text())
    assert list(record["phases"]) == ["pretrain"] and record["validation"]["source"] == "held-out automatically labelled training frames"
    assert (out / "rows" / "fpn-resnet34-pretrained" / "seed-0" / record["checkpoint"]).is_file()
    assert not (out / "rows" / "fpn-resnet34-supervised").exists()


def test_the_cfar_predictions_and_automatic_labels_on_a_cluster_are_the_run_in_one_process(label_free_run, tmp_path):
    """``zendar-bench --scheduler`` on a dataset without labels: the CFAR submission and the automatic
    labels' scene files and statistics, made one task per scene on 2 Dask workers, equal the run's."""
    pytest.importorskip("distributed")
    from distributed import LocalCluster

    from zendar_baselines.bench.configs import get_config
    from zendar_baselines.bench.context import RunContext
    from zendar_baselines.bench.unlabelled import STATISTICS_FILE, write_auto_labels_with_statistics, write_cfar_submission

    data, out, _ = label_free_run
    context = RunContext.open(data, get_config("tiny"), tmp_path / "run", "cpu")
    (tmp_path / "cfar").mkdir()
    (tmp_path / "labels").mkdir()
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0") as local:
        write_cfar_submission(context, tmp_path / "cfar", local.scheduler_address)
        write_auto_labels_with_statistics(context.dataset, ["drive-train"], tmp_path / "labels", local.scheduler_address)
    there = json.loads((tmp_path / "cfar" / "predictions.json").read_text())
    here = json.loads((out / "rows" / "cfar" / "predictions.json").read_text())
    assert there["results"] == here["results"]
    assert (tmp_path / "labels" / STATISTICS_FILE).read_bytes() == (out / "autolabels" / STATISTICS_FILE).read_bytes()
    store_files = sorted(path.name for path in (out / "autolabels" / "store").glob("*.npz"))
    assert store_files and all((tmp_path / "labels" / "store" / name).read_bytes()
                               == (out / "autolabels" / "store" / name).read_bytes() for name in store_files)


def test_a_second_run_reuses_every_step_and_verify_refuses(label_free_run, capsys):
    from zendar_baselines.bench.cli import main
    from zendar_baselines.bench.configs import Schedule, get_config
    from zendar_baselines.bench.run import BenchOptions, run_bench

    data, out, results = label_free_run
    config = replace(get_config("tiny"), models=("fpn-resnet34",), pretrain=Schedule(lr=1e-3, batch_size=4, epochs=2))
    again = run_bench(BenchOptions(config=config, data=data, out=out, seeds=1, device="cpu", jobs=1))
    assert "done in" not in capsys.readouterr().err  # every step reused
    assert again["rows"] == results["rows"]
    assert main(["verify", "--out", str(out)]) == 2
    assert "scored nothing" in capsys.readouterr().err
