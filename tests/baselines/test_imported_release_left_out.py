"""``zendar-bench`` on an imported release with scenes it cannot use whole: a scene without range-Doppler
cubes, or whose maps are smaller than the CFAR window. Each step leaves such a scene (or radar) out,
lists it with the reason among the skipped items, and runs on the rest; a row with no scene left is
skipped with the reason."""

from __future__ import annotations

import json
from dataclasses import replace

import pytest

from tests.baselines.test_imported_release import TIMES_S, write_release
from zendar_dataset.errors import ZendarError
from zendar_dataset.format import open_dataset

pytestmark = pytest.mark.slow  # imports release scenes; one run pretrains a CNN for an epoch

SMALL = (16, 8, 4)  # the CFAR window spans 13 Doppler cells
SMALL_REASON = "range-Doppler maps of 16 range x 8 Doppler cells, smaller than the CFAR window"
NO_CUBES = "no range-Doppler cubes (no radar streams)"


def _import(root, scenes: dict[str, tuple[str, tuple[int, int, int] | None]]):
    """A dataset of release scenes: scene id -> (split, cube shape or None for no cubes)."""
    from zendar_dataset.cli.data import main

    for scene_id, (split, cube_shape) in scenes.items():
        release = root / "release" / scene_id
        write_release(release / "2020-02-03_2252" / "001", cube_shape)
        assert main(["import-release", str(release), str(root / "data"), "--scene-id", scene_id, "--split", split]) == 0
    return root / "data"


def _bench(data, out, epochs: int = 1):
    from zendar_baselines.bench.configs import Schedule, get_config
    from zendar_baselines.bench.run import BenchOptions, run_bench

    config = replace(get_config("tiny"), models=("fpn-resnet34",), pretrain=Schedule(lr=1e-3, batch_size=4, epochs=epochs))
    return run_bench(BenchOptions(config=config, data=data, out=out, seeds=1, device="cpu", jobs=1))


def test_the_cfar_row_leaves_out_a_radar_whose_maps_are_smaller_than_its_window(tmp_path):
    data = _import(tmp_path, {"drive-test": ("test", (64, 32, 4)), "small-test": ("test", SMALL)})
    results = _bench(data, tmp_path / "out")
    cfar = results["rows"][0]
    assert cfar["key"] == "cfar" and cfar["done"] == f"predictions of the {2 * len(TIMES_S)} test frames"
    predictions = json.loads((tmp_path / "out" / "rows" / "cfar" / "predictions.json").read_text())
    assert any(predictions["results"][fid] for fid in predictions["results"] if fid.startswith("drive-test/"))
    small = [fid for fid in predictions["results"] if fid.startswith("small-test/")]
    assert len(small) == len(TIMES_S) and not any(predictions["results"][fid] for fid in small)
    left_out = [entry for entry in results["skipped"] if entry["what"].startswith("CFAR predictions")]
    assert [entry["what"] for entry in left_out] == ["CFAR predictions: scene small-test, radar left"]
    assert SMALL_REASON in left_out[0]["reason"]
    assert left_out[0]["reason"].endswith("the window spans 13 Doppler cells but the map has 8")
    table = (tmp_path / "out" / "table.md").read_text()
    assert f"| CFAR predictions | scene small-test, radar left | {left_out[0]['reason']} |" in table


def test_a_cfar_row_without_a_scene_left_is_skipped_with_the_reason(tmp_path, capsys):
    from zendar_baselines.bench.cli import main

    data = _import(tmp_path, {"small-test": ("test", SMALL)})
    assert main(["--quick", "--data", str(data), "--out", str(tmp_path / "out"), "--jobs", "1", "--device", "cpu"]) == 0
    err = capsys.readouterr().err
    assert "a bug" not in err and "[CFAR predictions] leaving out scene small-test, radar left: " + SMALL_REASON in err
    results = json.loads((tmp_path / "out" / "results.json").read_text())
    cfar = results["rows"][0]
    assert cfar["done"] is None and cfar["skipped"] == "predictions and scoring"
    assert cfar["reason"].startswith("every scene of split 'test' is left out: " + SMALL_REASON)
    assert results["submission"] is None and not (tmp_path / "out" / "rows" / "cfar" / "predictions.json").exists()


def test_automatic_labels_and_pretraining_leave_out_training_scenes_without_cubes_or_too_small(tmp_path, one_thread):
    data = _import(tmp_path, {"drive-train": ("train", (64, 32, 4)), "bare-train": ("train", None),
                              "small-train": ("train", SMALL), "bare-test": ("test", None)})
    results = _bench(data, tmp_path / "out")
    rows = {row["key"]: row for row in results["rows"]}
    assert rows["cfar"]["skipped"] == "predictions and scoring"
    assert rows["cfar"]["reason"] == f"every scene of split 'test' is left out: {NO_CUBES}"
    assert rows["fpn-resnet34-pretrained"]["done"] == "pretraining on the automatic labels, 1 seed(s)"
    assert {"what": "automatic labels and pretraining: scene bare-train", "reason": NO_CUBES} in results["skipped"]
    assert {"what": "CFAR predictions: scene bare-test", "reason": NO_CUBES} in results["skipped"]
    small = [entry for entry in results["skipped"] if entry["what"] == "automatic labels and pretraining: scene small-train, radar left"]
    assert len(small) == 1 and small[0]["reason"].startswith(SMALL_REASON)
    assert list(results["autolabel_statistics"]["scenes"]) == ["drive-train"]
    record = json.loads((tmp_path / "out" / "rows" / "fpn-resnet34-pretrained" / "seed-0" / "checkpoint.json").read_text())
    assert record["validation"]["scenes"] == ["drive-train"]
    assert "| automatic labels and pretraining | scene bare-train | " + NO_CUBES + " |" in (tmp_path / "out" / "table.md").read_text()


def test_automatic_labels_of_a_scene_without_cubes_say_why(tmp_path):
    from zendar_baselines.bench.autolabels import write_auto_labels

    data = _import(tmp_path, {"bare-train": ("train", None)})
    with pytest.raises(ZendarError, match="scene bare-train: no radar to label automatically: no range-Doppler cubes"):
        write_auto_labels(open_dataset(data), ["bare-train"], tmp_path / "labels", quality=False)


def test_a_test_scene_without_radar_or_sar_is_left_out_of_the_cfar_predictions(tmp_path):
    from tests.release.fixture import T0_S
    from tests.release.test_import_into_out import _tracklog_scene
    from zendar_dataset.cli.data import main

    data = _import(tmp_path, {"drive-test": ("test", (64, 32, 4))})
    _tracklog_scene(tmp_path / "release" / "poses" / "2020-02-04_1000" / "001", T0_S)  # format v1 allows a scene of poses only
    assert main(["import-release", str(tmp_path / "release" / "poses"), str(data), "--split", "test"]) == 0
    results = _bench(data, tmp_path / "out")
    cfar = results["rows"][0]
    assert cfar["key"] == "cfar" and cfar["done"] == f"predictions of the {len(TIMES_S)} test frames"
    left_out = [entry["what"] for entry in results["skipped"] if entry["what"].startswith("CFAR predictions")]
    assert left_out == ["CFAR predictions: scene 2020-02-04_1000_001"]
