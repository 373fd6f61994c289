"""Every rule of docs/format.md has a check in ``validate``: break one rule at a time in a valid
dataset and the message naming it appears (one test id per rule, in the page's order)."""

from __future__ import annotations

import json
import pathlib
import shutil

import numpy as np
import pytest

from tests.format.conftest import FRAME_NS, T0_NS, make_calibration, make_small_dataset
from tests.format.helpers import replace_array, set_attr
from zendar_dataset.format import open_dataset
from zendar_dataset.format.validate import validate_dataset

SAR_T = T0_NS + FRAME_NS * np.array([1, 3])  # the SAR frames of the small dataset's scene s0


@pytest.fixture(scope="module")
def template(tmp_path_factory) -> pathlib.Path:
    root = make_small_dataset(tmp_path_factory.mktemp("rules") / "ds", "zarr")
    assert validate_dataset(root) == []
    return root


def _document(root):
    return json.loads((root / "dataset.json").read_text())


def _edit_document(root, edit):
    document = _document(root)
    edit(document)
    (root / "dataset.json").write_text(json.dumps(document))


def _rename_scene(root, new_id):
    def edit(document):
        document["scenes"][new_id] = document["scenes"].pop("s0")
        document["splits"]["train"] = [new_id]

    _edit_document(root, edit)


def _calibration(root, edit):
    calibration = make_calibration()
    edit(calibration["sensors"])
    set_attr(root / "scenes/s0.zarr", "calibration", "calibration", calibration)


def _array(path, data):
    return lambda root: replace_array(root / "scenes/s0.zarr", path, None if data is None else np.asarray(data))


def _attr(key, value):
    return lambda root: set_attr(root / "scenes/s0.zarr", "", key, value)


def _rechunk_cube(root):
    cube = open_dataset(root).open_scene("s0").array("radar/left/cube")[...]
    import zarr

    group = zarr.open_group(str(root / "scenes/s0.zarr"), mode="a", use_consolidated=False)
    del group["radar/left/cube"]
    array = group.create_array("radar/left/cube", shape=cube.shape, dtype=cube.dtype, chunks=(2, *cube.shape[1:]))
    array[...] = cube


def _tracklog_quaternions(root):
    attitude = np.tile([1.0, 0.0, 0.0, 0.0], (40, 1))
    attitude[7] = [0.9, 0.1, 0.0, 0.0]
    replace_array(root / "scenes/s0.zarr", "tracklog/attitude_wxyz", attitude)


def _labels(name, values):
    return _array(f"labels/moving_cars/{name}", values)


def _remove_sar(root):
    for sensor in ("left", "right"):
        shutil.rmtree(root / "scenes/s0.zarr/sar" / sensor)
    from tests.format.helpers import reconsolidate

    reconsolidate(root / "scenes/s0.zarr")


# (rule as docs/format.md states it, how to break it, fragment of the message validate prints)
RULES = {
    "dataset-json-present": (lambda root: (root / "dataset.json").unlink(), "expected dataset.json at the dataset root, found none"),
    "format-name": (lambda root: _edit_document(root, lambda d: d.update(format="other")), "format: expected 'zendar-dataset', found 'other'"),
    "format-version": (lambda root: _edit_document(root, lambda d: d.update(format_version=2)), "format_version: expected 1, found 2"),
    "name-is-a-string": (lambda root: _edit_document(root, lambda d: d.update(name=7)), "name: expected a string, found 7"),
    "scene-path-relative-with-suffix": (
        lambda root: _edit_document(root, lambda d: d["scenes"]["s0"].update(path="/abs/s0.zarr")),
        "scenes.s0.path: expected a relative path ending in .zarr or .h5, found '/abs/s0.zarr'",
    ),
    "scene-id-without-slash": (lambda root: _rename_scene(root, "a/b"), "expected scene ids without '/' and not starting with '.', found 'a/b'"),
    "scene-id-not-hidden": (lambda root: _rename_scene(root, ".s0"), "expected scene ids without '/' and not starting with '.', found '.s0'"),
    "split-ids-are-scenes": (
        lambda root: _edit_document(root, lambda d: d["splits"]["val"].append("ghost")),
        "splits.val: expected scene 'ghost' in scenes, found no entry",
    ),
    "scene-in-one-split": (
        lambda root: _edit_document(root, lambda d: d["splits"]["test"].append("s0")),
        "splits: expected each scene in one split, found 's0' in ['test', 'train']",
    ),
    "train-val-test-present": (
        lambda root: _edit_document(root, lambda d: d["splits"].pop("test")),
        "splits: expected ['train', 'val', 'test'] always present (possibly empty), found no ['test']",
    ),
    "one-chunk-per-frame": (_rechunk_cube, "s0: radar/left/cube: expected one chunk per frame [1, 16, 8, 4], found chunks [2, 16, 8, 4]"),
    "timestamps-int64": (_array("camera/front/timestamp_ns", np.arange(4, dtype=np.float64)), "s0: camera/front/timestamp_ns: expected dtype int64, found float64"),
    "timestamps-strictly-increasing": (
        _array("radar/right/timestamp_ns", [5, 6, 6, 7]),
        "s0: radar/right/timestamp_ns: expected strictly increasing timestamps, found 6 at index 2 after 6",
    ),
    "label-timestamps-non-decreasing": (
        _labels("timestamp_ns", SAR_T[::-1]),
        f"s0: labels/moving_cars/timestamp_ns: expected non-decreasing timestamps, found {SAR_T[0]} at index 1 after {SAR_T[1]}",
    ),
    "scene-id-attribute": (_attr("scene_id", "s9"), "s0: /: expected attribute scene_id 's0' (dataset.json), found 's9'"),
    "time-reference-gps": (_attr("time_reference", "utc"), "s0: /: expected attribute time_reference 'gps', found 'utc'"),
    "enu-origin-keys": (_attr("enu_origin", {"lat_deg": 1.0, "lon_deg": 2.0}), "s0: /: expected attribute enu_origin with keys"),
    "enu-origin-finite": (
        _attr("enu_origin", {"lat_deg": float("nan"), "lon_deg": 2.0, "height_m": 0.0}),
        "s0: /: expected attribute enu_origin with finite numeric values",
    ),
    "calibration-attribute": (
        lambda root: set_attr(root / "scenes/s0.zarr", "calibration", "calibration", None),
        "s0: calibration: expected attribute 'calibration', found nothing",
    ),
    "calibration-unit-quaternion": (
        lambda root: _calibration(root, lambda s: s["top"].update(rotation_wxyz=[1.0, 0.1, 0.0, 0.0])),
        "s0: calibration: calibration: sensors.top.rotation_wxyz: expected a unit quaternion, found norm 1.004987562",
    ),
    "every-sensor-calibrated": (
        lambda root: _calibration(root, lambda s: s.pop("right")),
        "s0: calibration: expected an entry for sensor 'right' (radar/right), found none",
    ),
    "radar-bins-positive": (
        lambda root: _calibration(root, lambda s: s["left"].update(range_bin_m=-0.18)),
        "sensors.left.range_bin_m: expected a positive number, found -0.18",
    ),
    "imu-with-tracklog": (
        lambda root: _calibration(root, lambda s: s.pop("imu")),
        "s0: calibration: expected an entry for sensor 'imu' (tracklog), found none",
    ),
    "camera-size-matches-calibration": (
        lambda root: _calibration(root, lambda s: s["front"].update(width=9)),
        "s0: camera/front/image: expected [C, 6, 9, 3] (calibration height, width), found [4, 6, 8, 3]",
    ),
    "antennas-match-rx-positions": (
        lambda root: _calibration(root, lambda s: s["right"].update(rx_positions_m=[[0.0, 0.0, 0.0]] * 3)),
        "s0: radar/right/cube: expected A=3 antennas (rx_positions_m of 'right'), found [4, 16, 8, 4]",
    ),
    "array-dtype": (_array("sar/left/image", np.zeros((2, 12, 10), np.complex128)), "s0: sar/left/image: expected dtype complex64 (or uint32, float32 for a magnitude-only image), found complex128"),
    "array-fixed-size": (_array("sar/right/di_ecef", np.zeros((2, 2))), "s0: sar/right/di_ecef: expected size 3 on axis 1"),
    "stream-length-n": (_array("sar/right/origin_ecef", np.zeros((3, 3))), "s0: sar/right/origin_ecef: expected 2 rows"),
    "sensor-group-has-all-arrays": (_array("sar/left/aperture_ns", None), "s0: sar/left/aperture_ns: expected an array [N, 2] int64, found nothing"),
    "aperture-start-not-after-end": (
        _array("sar/left/aperture_ns", np.stack([SAR_T + 5, SAR_T - 5], axis=1)),
        "s0: sar/left/aperture_ns: expected start <= end, found 2 frames with start > end (first 0)",
    ),
    "tracklog-unit-quaternions": (
        _tracklog_quaternions,
        "s0: tracklog/attitude_wxyz: expected unit quaternions, found 1 with |q| != 1 (first at 7: 0.905538514)",
    ),
    "lidar-offsets": (
        lambda root: replace_array(root / "scenes/s0.zarr", "lidar/top/offsets", np.array([0, 2, 1, 3, 3])),
        "s0: lidar/top/offsets: expected non-decreasing offsets from 0 to",
    ),
    "finite-values": (
        _array("sar/left/origin_ecef", [[1.0, 2.0, 3.0], [np.inf, 0.0, 0.0]]),
        "s0: sar/left/origin_ecef: expected finite values, found 1 NaN/inf",
    ),
    "label-length-positive": (_labels("length", [4.5, 0.0]), "s0: labels/moving_cars/length: expected positive metres, found 1 values <= 0"),
    "label-width-positive": (_labels("width", [-1.0, 1.8]), "s0: labels/moving_cars/width: expected positive metres, found 1 values <= 0"),
    "label-values-finite": (_labels("vx", [np.nan, 1.0]), "s0: labels/moving_cars/vx: expected finite values, found 1 NaN/inf"),
    "label-fields-equal-length": (_labels("yaw", [0.1, 0.2, 0.3]), "s0: labels/moving_cars/yaw: expected 2 rows"),
    "labels-refer-to-sar-frames": (
        _labels("timestamp_ns", [SAR_T[0], SAR_T[0] + 1]),
        "s0: labels/moving_cars/timestamp_ns: expected timestamps of sar/left frames, found 1 that are not",
    ),
    "labels-need-a-sar-stream": (_remove_sar, "s0: labels/moving_cars: expected a SAR stream whose frames the labels refer to, found none"),
    "checksum-algorithm-known": (_attr("chunk_checksums", "md5"), "s0: /: expected attribute chunk_checksums 'crc32c' or none, found 'md5'"),
    "every-array-has-checksums": (
        lambda root: set_attr(root / "scenes/s0.zarr", "tracklog/position_ecef", "chunk_crc32c", None),
        "s0: tracklog/position_ecef: attribute chunk_crc32c: expected a string of lowercase hex digits, found NoneType",
    ),
    "one-checksum-per-chunk": (
        lambda root: set_attr(root / "scenes/s0.zarr", "radar/left/cube", "chunk_crc32c", "0" * 24),
        "s0: radar/left/cube: attribute chunk_crc32c: expected 4 checksums (32 hex digits, one per chunk), found 24 hex digits",
    ),
}


@pytest.mark.parametrize("rule", list(RULES))
def test_validate_names_the_broken_rule(template, tmp_path, rule):
    breakage, message = RULES[rule]
    root = pathlib.Path(shutil.copytree(template, tmp_path / "ds"))
    breakage(root)
    problems = validate_dataset(root)
    assert any(message in problem for problem in problems), (message, problems)
