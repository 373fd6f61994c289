"""The release's uint32 SAR magnitudes: imported exactly (16777217 stays 16777217), at half the bytes of
complex64, and read back exactly by the scene reader, ``ZendarDataset`` and ``SarFrames``."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.release import encoder as enc
from tests.release.fixture import COLS, ROWS, T0_S, enu_to_ecef, sar_frame, vehicle, wxyz
from zendar_dataset.dataset import ZendarDataset
from zendar_dataset.format import open_dataset
from zendar_dataset.format.validate import validate_dataset
from zendar_dataset.release import import_release
from zendar_dataset.sar.frames import SarFrames

SCENE_ID = "2020-02-03_2252_001"
BIG = [2**24 + 1, 2**32 - 1, 2**24 + 3]  # float32 (complex64) rounds each of these
FRAMES = 4


def _magnitudes(k: int) -> np.ndarray:
    """Frame k's [ROWS, COLS] uint32 magnitudes: small values, one big one at (k + 1, 2k + 1)."""
    image = (np.arange(ROWS * COLS, dtype=np.uint32).reshape(ROWS, COLS) + 7 * k).astype("<u4")
    image[k + 1, 2 * k + 1] = BIG[k % len(BIG)]
    return image


def _write_release(root, complex_frame: int | None = None) -> None:
    """One radar's 2020 images (pixel (i, j) at flat j*ROWS + i, as the SDK viewer reads) and a tracklog."""
    scene = root / "2020-02-03_2252" / "001"
    images = []
    for k in range(FRAMES):
        frame = sar_frame("left", 0.1 * k, k)
        p_enu, R_ecef_imu, _ = vehicle(0.1 * k)
        if k == complex_frame:
            data = _magnitudes(k).astype("<c8").T.tobytes()  # 8 bytes per pixel: complex
        else:
            data = _magnitudes(k).T.tobytes()
        images.append(
            enc.image_2020(frame.timestamp_s, wxyz(R_ecef_imu), enu_to_ecef(p_enu), k, frame.origin_ecef, frame.di_ecef,
                           frame.dj_ecef, ROWS, COLS, data)
        )
    enc.write_stream(scene / "1739000J1Q_images.pbs", images)
    poses = []
    for k, t in enumerate(np.arange(-0.2, 0.6, 0.02)):
        p_enu, R_ecef_imu, _ = vehicle(float(t))
        poses.append(enc.position_record(T0_S + float(t), wxyz(R_ecef_imu), enu_to_ecef(p_enu), k))
    enc.write_stream(scene / "vn200.pbs", poses)


@pytest.fixture(scope="module", params=["zarr", "hdf5"])
def imported(request, tmp_path_factory):
    root = tmp_path_factory.mktemp(f"magnitudes_{request.param}")
    _write_release(root / "release")
    import_release(root / "release", root / "out", backend=request.param)
    return request.param, root / "out"


def _sar_sensor(out) -> str:
    (sensor,) = open_dataset(out).open_scene(SCENE_ID).sensors("sar")
    return sensor


def test_big_magnitudes_round_trip_exactly_through_store_and_dataset(imported):
    _, out = imported
    assert validate_dataset(out) == []
    sensor = _sar_sensor(out)
    reader = open_dataset(out).open_scene(SCENE_ID)
    images = reader.array(f"sar/{sensor}/image")
    assert images.dtype == np.uint32 and images.shape == (FRAMES, ROWS, COLS)
    assert reader.sar_magnitude_only(sensor)
    for k in range(FRAMES):
        np.testing.assert_array_equal(images[k], _magnitudes(k))
    assert int(images[0][1, 1]) == 16777217
    dataset = ZendarDataset(out, split="train", streams=("sar",), reference=f"sar/{sensor}")
    assert len(dataset) == FRAMES
    for k in range(FRAMES):
        image = dataset[k]["sar"][sensor]["image"]
        assert image.dtype == np.uint32
        np.testing.assert_array_equal(image, _magnitudes(k))
    assert int(dataset[0]["sar"][sensor]["image"][1, 1]) == 16777217
    batch = ZendarDataset.collate([dataset[0], dataset[1]])["sar"][sensor]["image"]
    assert int(batch[0, 1, 1].double()) == 16777217
    sar = SarFrames(reader)
    assert int(sar.magnitude(sensor, 0)[0][1, 1]) == 16777217


def test_a_magnitude_stream_stores_half_the_bytes_of_complex64(imported):
    backend, out = imported
    sensor = _sar_sensor(out)
    reader = open_dataset(out).open_scene(SCENE_ID)
    assert reader.array(f"sar/{sensor}/image")[...].nbytes == FRAMES * ROWS * COLS * 4  # complex64: 8 per pixel
    if backend == "zarr":
        chunks = out / "scenes" / f"{SCENE_ID}.zarr" / "sar" / sensor / "image" / "c"
        stored = sum(f.stat().st_size for f in chunks.rglob("*") if f.is_file())
    else:
        stored = reader.store_root[f"sar/{sensor}/image"].id.get_storage_size()
    assert stored == FRAMES * ROWS * COLS * 4


def test_a_complex_frame_in_a_magnitude_stream_is_skipped_and_counted(tmp_path):
    _write_release(tmp_path / "release", complex_frame=2)
    import_release(tmp_path / "release", tmp_path / "out")
    assert validate_dataset(tmp_path / "out") == []
    sensor = _sar_sensor(tmp_path / "out")
    reader = open_dataset(tmp_path / "out").open_scene(SCENE_ID)
    images = reader.array(f"sar/{sensor}/image")
    assert images.dtype == np.uint32 and images.shape[0] == FRAMES - 1
    np.testing.assert_array_equal(images[2], _magnitudes(3))
    (scene,) = json.loads((tmp_path / "out" / "release_import.json").read_text())["scenes"]
    (stream,) = [s for s in scene["streams"] if s["path"].endswith("_images.pbs")]
    assert "1 frames: complex pixels (complex64) differ from the stream's first frame's magnitude (uint32)" in stream["skipped"]
