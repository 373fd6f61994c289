"""Every kind of bad input raises ZendarFormatError naming the scene, the path and the expectation."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.format.conftest import CAM_H, CAM_W, ENU_ORIGIN, T0_NS, A, D, R, make_calibration, make_dataset
from tests.format.helpers import corrupt_chunk, replace_array, set_attr
from zendar_dataset.errors import ZendarFormatError
from zendar_dataset.format import FORMAT_NAME, FORMAT_VERSION, SceneReader, SceneWriter, open_dataset
from zendar_dataset.format.reader import check_dataset_json


def _scene_path(root, scene_id, backend):
    return root / "scenes" / f"{scene_id}{'.zarr' if backend == 'zarr' else '.h5'}"


def _open_error(root, scene_id="s0") -> ZendarFormatError:
    with pytest.raises(ZendarFormatError) as info:
        open_dataset(root).open_scene(scene_id)
    return info.value


def test_missing_array(dataset_root, backend):
    replace_array(_scene_path(dataset_root, "s0", backend), "sar/left/origin_ecef", None)
    error = _open_error(dataset_root)
    assert "s0: sar/left/origin_ecef: expected an array [N, 3] float64, found nothing" in str(error)


def test_wrong_dtype(dataset_root, backend):
    replace_array(_scene_path(dataset_root, "s0", backend), "radar/left/cube", np.zeros((4, 16, 8, 4), np.complex128))
    assert "s0: radar/left/cube: expected dtype complex64, found complex128" in str(_open_error(dataset_root))


def test_wrong_shape(dataset_root, backend):
    path = _scene_path(dataset_root, "s1", backend)
    replace_array(path, "tracklog/position_ecef", np.zeros((40, 2)))
    replace_array(path, "camera/front/image", np.zeros((3, 6, 8, 3), np.uint8))
    error = _open_error(dataset_root, "s1")
    assert "s1: tracklog/position_ecef: expected size 3 on axis 1" in str(error)
    assert "s1: camera/front/image: expected 4 rows" in str(error) and "N=4 timestamps" in str(error)
    assert len(error.problems) == 2


def test_missing_attribute_and_calibration(dataset_root, backend):
    path = _scene_path(dataset_root, "s0", backend)
    set_attr(path, "", "time_reference", "utc")
    set_attr(path, "calibration", "calibration", None)
    error = _open_error(dataset_root)
    assert "s0: /: expected attribute time_reference 'gps', found 'utc'" in str(error)
    assert "s0: calibration: expected attribute 'calibration', found nothing" in str(error)


def test_non_increasing_timestamps(dataset_root, backend):
    path = _scene_path(dataset_root, "s2", backend)
    t = np.array([10, 20, 20, 30], dtype=np.int64)
    replace_array(path, "camera/front/timestamp_ns", t)
    scene = open_dataset(dataset_root).open_scene("s2")  # metadata is fine
    with pytest.raises(ZendarFormatError, match="s2: camera/front/timestamp_ns: expected strictly increasing timestamps, found 20 at index 2 after 20"):
        scene.timestamps("camera/front")


@pytest.fixture
def zarr_root(tmp_path):
    return make_dataset(tmp_path / "ds-zarr", "zarr")


def test_truncated_chunk_zarr(zarr_root):
    dataset_root = zarr_root
    for array_path in ("radar/left/cube", "camera/front/image"):  # raw and compressed chunks
        corrupt_chunk(_scene_path(dataset_root, "s0", "zarr"), array_path, 2)
        scene = open_dataset(dataset_root).open_scene("s0")
        scene.array(array_path)[1]  # other chunks still read
        for key in (2, slice(1, 3), (2, 0)):
            with pytest.raises(ZendarFormatError, match=f"s0: {array_path}: expected readable .* chunks, found a truncated or corrupt chunk"):
                scene.array(array_path)[key]


def test_missing_chunk_is_an_error_not_zeros(zarr_root):
    """The store records checksums, so a chunk that is not stored is an error, not the fill value."""
    scene_path = _scene_path(zarr_root, "s0", "zarr")
    (scene_path / "radar/left/cube/c/1/0/0/0").unlink()
    (scene_path / "camera/front/image/c/2/0/0/0").unlink()  # compressed: read through zarr, not directly
    scene = open_dataset(zarr_root).open_scene("s0")
    with pytest.raises(ZendarFormatError, match="s0: radar/left/cube: .* chunk of frame 1 is missing"):
        scene.array("radar/left/cube")[1]
    with pytest.raises(ZendarFormatError, match=r"s0: camera/front/image: expected every chunk stored .*found chunk \[2, 0, 0, 0\] missing"):
        scene.array("camera/front/image")[1:3]
    assert scene.array("camera/front/image")[1].shape == (CAM_H, CAM_W, 3)


def test_corrupt_and_truncated_hdf5(tmp_path):
    path = tmp_path / "z.h5"
    calibration = make_calibration()
    with SceneWriter(path, "z", enu_origin=ENU_ORIGIN, calibration=calibration) as writer:
        for k in range(3):  # constant images compress, so LZF really encodes them
            writer.append_camera("front", T0_NS + k, np.full((CAM_H, CAM_W, 3), 9, np.uint8))
            writer.append_radar("left", T0_NS + k, np.ones((R, D, A), np.complex64))
    corrupt_chunk(path, "camera/front/image", 1)
    scene = SceneReader(path)
    assert scene.array("camera/front/image")[0][0, 0, 0] == 9
    with pytest.raises(ZendarFormatError, match="z: camera/front/image: expected readable uint8 chunks, found a truncated or corrupt chunk"):
        scene.array("camera/front/image")[1]
    scene.close()
    size = path.stat().st_size
    with open(path, "r+b") as handle:
        handle.truncate(size // 2)
    with pytest.raises(ZendarFormatError, match="expected a readable zarr/HDF5 store"):
        SceneReader(path, scene_id="z")


def test_unknown_split_and_scene(dataset_root):
    index = open_dataset(dataset_root)
    with pytest.raises(ZendarFormatError, match="expected one of \\['test', 'train', 'val'\\], found unknown split 'training'"):
        index.scene_ids("training")
    with pytest.raises(ZendarFormatError, match="found unknown scene 's9'"):
        index.open_scene("s9")
    scene = index.open_scene("s0")
    with pytest.raises(ZendarFormatError, match="s0: radar/middle: expected one of the scene's streams"):
        scene.timestamps("radar/middle")
    with pytest.raises(ZendarFormatError, match="s0: radar/left/nope: expected an array, found nothing"):
        scene.array("radar/left/nope")


def test_bad_dataset_json(tmp_path, dataset_root):
    with pytest.raises(ZendarFormatError, match="expected dataset.json at the dataset root"):
        open_dataset(tmp_path / "nowhere")
    document = json.loads((dataset_root / "dataset.json").read_text())
    document["format_version"] = 2
    document["splits"]["val"].append("ghost")
    (dataset_root / "dataset.json").write_text(json.dumps(document))
    with pytest.raises(ZendarFormatError) as info:
        open_dataset(dataset_root)
    assert len(info.value.problems) == 2
    assert "format_version: expected 1, found 2" in str(info.value)
    assert "splits.val: expected scene 'ghost' in scenes" in str(info.value)


def test_dataset_json_scenes_and_splits_must_be_objects():
    document = {"format": FORMAT_NAME, "format_version": FORMAT_VERSION, "name": "x", "scenes": ["s0"], "splits": None}
    assert check_dataset_json(document, "dataset.json") == [
        "dataset.json: scenes: expected {scene_id: {\"path\": ...}}, found ['s0']",
        "dataset.json: splits: expected {split: [scene_id, ...]}, found None",
    ]


def test_scene_id_mismatch_and_missing_store(dataset_root, backend):
    document = json.loads((dataset_root / "dataset.json").read_text())
    document["scenes"]["s1"] = document["scenes"]["s0"]
    (dataset_root / "dataset.json").write_text(json.dumps(document))
    assert "s1: /: expected attribute scene_id 's1' (dataset.json), found 's0'" in str(_open_error(dataset_root, "s1"))
    import shutil

    path = _scene_path(dataset_root, "s2", backend)
    shutil.rmtree(path) if path.is_dir() else path.unlink()
    assert "s2: expected a scene store at" in str(_open_error(dataset_root, "s2"))


def test_validate_reports_stale_consolidated_metadata(zarr_root):
    import zarr

    from zendar_dataset.format.validate import validate_scene

    path = _scene_path(zarr_root, "s0", "zarr")
    group = zarr.open_group(str(path), mode="a", use_consolidated=False)
    del group["camera"]  # edited without refreshing the consolidated metadata
    problems = validate_scene(path, "s0")
    assert problems == [
        "s0: zarr.json: expected consolidated metadata matching the store, found 4 differing paths "
        "(first 'camera'); re-run zarr.consolidate_metadata"
    ]
