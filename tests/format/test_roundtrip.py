"""Writing then reading gives back every array bit for bit and every attribute, in both backends."""

from __future__ import annotations

import json
import multiprocessing
import pickle

import numpy as np
import pytest

from tests.format.conftest import CAM_H, CAM_W, ENU_ORIGIN, SAR_H, SAR_W, T0_NS, A, D, R, make_calibration
from tests.format.helpers import chunk_rows, crc32c_hex, dump
from zendar_dataset.errors import ZendarFormatError
from zendar_dataset.format import Calibration, DatasetWriter, SceneReader, SceneWriter, open_dataset


def _expected_scene(rng):
    """Arrays a scene should contain, built independently of the writer."""
    n = 3
    radar_t = T0_NS + np.arange(n) * 50_000_000
    cubes = (rng.standard_normal((n, R, D, A)) + 1j * rng.standard_normal((n, R, D, A))).astype(np.complex64)
    sar_t = radar_t[[0, 2]]
    sar = (rng.standard_normal((2, SAR_H, SAR_W)) + 1j * rng.standard_normal((2, SAR_H, SAR_W))).astype(np.complex64)
    origin = rng.uniform(-6e6, 6e6, (2, 3))
    di, dj = rng.standard_normal((2, 3)), rng.standard_normal((2, 3))
    aperture = np.stack([sar_t - 7, sar_t + 9], axis=1)
    images = rng.integers(0, 256, (n, CAM_H, CAM_W, 3), dtype=np.uint8)
    sweeps = [rng.standard_normal((k, 4)).astype(np.float32) for k in (5, 0, 70_000)]
    track_t = T0_NS + np.arange(20) * 10_000_000
    position = rng.uniform(-6e6, 6e6, (20, 3))
    quaternion = rng.standard_normal((20, 4))
    quaternion /= np.linalg.norm(quaternion, axis=1, keepdims=True)
    labels = {
        "timestamp_ns": np.array([sar_t[0], sar_t[0], sar_t[1]], dtype=np.int64),
        "x": rng.standard_normal(3), "y": rng.standard_normal(3), "length": np.array([4.0, 5.0, 4.2]),
        "width": np.array([1.8, 2.0, 1.9]), "yaw": rng.standard_normal(3), "vx": rng.standard_normal(3),
        "vy": rng.standard_normal(3), "track_id": np.array([1, 2, 1], dtype=np.int64),
    }
    return locals()


@pytest.mark.parametrize("suffix", [".zarr", ".h5"])
def test_scene_round_trip_is_bit_identical(tmp_path, suffix):
    e = _expected_scene(np.random.default_rng(1))
    path = tmp_path / f"scene{suffix}"
    with SceneWriter(path, "scene-a", enu_origin=ENU_ORIGIN, calibration=make_calibration()) as writer:
        for k in range(3):
            writer.append_radar("left", int(e["radar_t"][k]), e["cubes"][k])
            writer.append_camera("front", int(e["radar_t"][k]) + 1, e["images"][k])
            writer.append_lidar("top", int(e["radar_t"][k]) + 2, e["sweeps"][k])
        for m in range(2):
            writer.append_sar("left", int(e["sar_t"][m]), e["sar"][m], e["origin"][m], e["di"][m], e["dj"][m], e["aperture"][m])
        writer.write_tracklog(e["track_t"], e["position"], e["quaternion"])
        writer.write_labels(e["labels"])
    arrays, attrs = dump(path)
    offsets = np.cumsum([0] + [len(s) for s in e["sweeps"]])
    expected = {
        "radar/left/timestamp_ns": e["radar_t"], "radar/left/cube": e["cubes"],
        "sar/left/timestamp_ns": e["sar_t"], "sar/left/image": e["sar"], "sar/left/origin_ecef": e["origin"],
        "sar/left/di_ecef": e["di"], "sar/left/dj_ecef": e["dj"], "sar/left/aperture_ns": e["aperture"],
        "camera/front/timestamp_ns": e["radar_t"] + 1, "camera/front/image": e["images"],
        "lidar/top/timestamp_ns": e["radar_t"] + 2, "lidar/top/points": np.concatenate(e["sweeps"]),
        "lidar/top/offsets": offsets, "tracklog/timestamp_ns": e["track_t"], "tracklog/position_ecef": e["position"],
        "tracklog/attitude_wxyz": e["quaternion"],
        **{f"labels/moving_cars/{k}": v for k, v in e["labels"].items()},
    }
    assert sorted(arrays) == sorted(expected)
    for name, value in expected.items():
        stored = arrays[name]
        assert stored.dtype == np.asarray(value).dtype.newbyteorder("=") or name.endswith("offsets"), name
        assert stored.tobytes() == np.ascontiguousarray(value, dtype=stored.dtype).tobytes(), name
    assert arrays["lidar/top/offsets"].dtype == np.int64
    assert attrs[""] == {
        "scene_id": "scene-a", "time_reference": "gps", "enu_origin": ENU_ORIGIN, "chunk_checksums": "crc32c"
    }
    # Every array records the CRC-32C of each chunk's values, computed here from the values written.
    for name, value in expected.items():
        rows = chunk_rows(path, name)
        assert attrs[name]["chunk_crc32c"] == crc32c_hex(np.asarray(value, dtype=arrays[name].dtype), rows), name
    assert len(attrs["lidar/top/points"]["chunk_crc32c"]) == 2 * 8  # 70 005 rows: two chunks of 65 536
    assert attrs["calibration"]["calibration"] == Calibration.from_json(make_calibration()).to_json()

    scene = SceneReader(path)
    assert scene.backend == ("zarr" if suffix == ".zarr" else "hdf5")
    assert scene.scene_id == "scene-a" and scene.enu_origin == ENU_ORIGIN
    assert scene.sensors("radar") == ["left"] and scene.sensors("camera") == ["front"]
    np.testing.assert_array_equal(scene.timestamps("sar/left"), e["sar_t"])
    cube = scene.array("radar/left/cube")
    assert cube.shape == (3, R, D, A) and cube.chunks == (1, R, D, A) and cube.dtype == np.complex64
    assert cube[1].tobytes() == e["cubes"][1].tobytes()
    for k, sweep in enumerate(e["sweeps"]):
        assert scene.lidar_points("top", k).tobytes() == sweep.tobytes()
    every_point, offsets = scene.lidar_sweeps("top")  # all sweeps in one read
    assert offsets.tolist() == np.cumsum([0, *(len(sweep) for sweep in e["sweeps"])]).tolist()
    assert [every_point[a:b].tobytes() for a, b in zip(offsets[:-1], offsets[1:])] == [s.tobytes() for s in e["sweeps"]]
    labels = scene.labels()
    for name, value in e["labels"].items():
        np.testing.assert_array_equal(labels[name], value)
    radar = scene.calibration.radar("left")
    assert radar.range_bin_m == 0.18 and radar.rx_positions_m.shape == (A, 3)
    assert scene.has("tracklog/position_ecef") and not scene.has("radar/right")
    scene.close()


def test_dataset_index(dataset_root):
    index = open_dataset(dataset_root)
    assert index.name == "tiny"
    assert index.scene_ids("train") == ["s0", "s1"] and index.scene_ids("test") == ["s3"]
    assert index.open_scene("s3").labels() is None
    scene = index.open_scene("s0")
    assert scene.sensors("sar") == ["left", "right"]
    assert len(scene.timestamps("radar/left")) == 4


def _read_in_child(scene, queue):
    queue.put(scene.array("radar/left/cube")[2].tobytes())


@pytest.mark.parametrize("method", ["fork", "spawn"])
def test_reader_works_in_child_processes(dataset_root, method):
    scene = open_dataset(dataset_root).open_scene("s1")
    expected = scene.array("radar/left/cube")[2].tobytes()  # parent handle is open before the fork
    context = multiprocessing.get_context(method)
    queue = context.Queue()
    child = context.Process(target=_read_in_child, args=(scene, queue))
    child.start()
    got = queue.get(timeout=60)
    child.join(timeout=60)
    assert child.exitcode == 0 and got == expected
    assert scene.array("radar/left/cube")[2].tobytes() == expected


def test_pickle_keeps_location_not_handle(dataset_root):
    scene = open_dataset(dataset_root).open_scene("s2")
    scene.timestamps("radar/left")
    blob = pickle.dumps(scene)
    assert len(blob) < 20_000
    copy = pickle.loads(blob)
    assert copy.scene_id == "s2"
    np.testing.assert_array_equal(copy.timestamps("radar/left"), scene.timestamps("radar/left"))
    assert copy.array("sar/left/image")[0].tobytes() == scene.array("sar/left/image")[0].tobytes()


def test_writer_rejects_bad_frames(tmp_path):
    with pytest.raises(ZendarFormatError, match="strictly increasing"):
        with SceneWriter(tmp_path / "a.zarr", "a", enu_origin=ENU_ORIGIN, calibration=make_calibration()) as writer:
            cube = np.zeros((R, D, A), np.complex64)
            writer.append_radar("left", T0_NS, cube)
            writer.append_radar("left", T0_NS, cube)
    with SceneWriter(tmp_path / "b.h5", "b", enu_origin=ENU_ORIGIN, calibration=make_calibration()) as writer:
        with pytest.raises(ZendarFormatError, match="expected every frame of shape"):
            writer.append_radar("left", T0_NS, np.zeros((R, D, A), np.complex64))
            writer.append_radar("left", T0_NS + 1, np.zeros((R + 1, D, A), np.complex64))
        with pytest.raises(ZendarFormatError, match="A=4 antennas"):
            writer.append_radar("right", T0_NS, np.zeros((R, D, 3), np.complex64))
        with pytest.raises(ZendarFormatError, match="sensor 'nope'"):
            writer.append_radar("nope", T0_NS, np.zeros((R, D, A), np.complex64))
        with pytest.raises(ZendarFormatError, match="expected uint8"):
            writer.append_camera("front", T0_NS, np.zeros((CAM_H, CAM_W, 3), np.float32))
        with pytest.raises(ZendarFormatError, match="height=6, width=8"):
            writer.append_camera("front", T0_NS, np.zeros((CAM_H + 1, CAM_W, 3), np.uint8))
        with pytest.raises(ZendarFormatError, match="unit quaternions"):
            writer.write_tracklog([1, 2], np.zeros((2, 3)), [[1, 0, 0, 0], [2, 0, 0, 0]])
        with pytest.raises(ZendarFormatError, match="missing \\['yaw'\\]"):
            writer.write_labels({k: np.zeros(1) for k in ("timestamp_ns", "x", "y", "length", "width", "vx", "vy", "track_id")})
    # The rejected appends left the stream consistent: one frame, valid scene.
    scene = SceneReader(tmp_path / "b.h5")
    assert len(scene.timestamps("radar/left")) == 1 and scene.array("radar/left/cube").shape[0] == 1


def test_bad_calibration_lists_every_problem():
    calibration = make_calibration()
    calibration["sensors"]["left"]["rx_positions_m"] = [[0, 0]]
    calibration["sensors"]["front"]["K"] = [[1, 0], [0, 1]]
    calibration["sensors"]["top"]["rotation_wxyz"] = [2.0, 0, 0, 0]
    del calibration["sensors"]["imu"]["translation_m"]
    with pytest.raises(ZendarFormatError) as info:
        Calibration.from_json(calibration)
    text = "\n".join(info.value.problems)
    assert len(info.value.problems) == 4
    for fragment in ("left.rx_positions_m", "front.K", "top.rotation_wxyz", "imu: missing translation_m"):
        assert fragment in text


@pytest.mark.parametrize(
    ("rx_positions_m", "found"), [([[0, 0, 0], [0, 1]], "None"), ([["a", 0, 0]], "None"), (None, "[]")]
)
def test_unreadable_rx_positions_are_a_problem_not_a_crash(rx_positions_m, found):
    calibration = make_calibration()
    calibration["sensors"]["left"]["rx_positions_m"] = rx_positions_m
    with pytest.raises(ZendarFormatError) as info:
        Calibration.from_json(calibration)
    assert info.value.problems == [f"calibration: sensors.left.rx_positions_m: expected shape [A, 3] with A >= 1, found {found}"]


def test_calibration_json_round_trip():
    calibration = Calibration.from_json(make_calibration())
    again = Calibration.from_json(calibration.to_json())
    from_text = Calibration.from_json(json.loads(json.dumps(make_calibration())))
    assert again.to_json() == calibration.to_json() == from_text.to_json()
    assert again.to_json()["sensors"]["left"]["rx_positions_m"] == make_calibration()["sensors"]["left"]["rx_positions_m"]
    assert type(again.sensors["front"]).__name__ == "CameraCalibration" and again.camera("front").width == CAM_W
    with pytest.raises(ZendarFormatError, match="expected radar calibration for sensor 'front'"):
        again.radar("front")
