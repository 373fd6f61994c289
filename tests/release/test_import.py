"""``zendar-data import-release``: a synthetic release tree -> a valid format-v1 dataset with the geometry intact."""

from __future__ import annotations

import hashlib
import shutil
import json
import pathlib

import numpy as np
import pytest

from tests.release import encoder as enc
from tests.release.fixture import COLS, ROWS, SERIALS, T0_S, build_release
from zendar_dataset.format import open_dataset, stores
from zendar_dataset.format.validate import validate_dataset
from zendar_dataset.geometry.frames import ecef_to_sar_pixel
from zendar_dataset.release import iter_messages
from zendar_dataset.release.records import gps_seconds_to_ns


def run(*args, capsys) -> tuple[int, str, str]:
    from zendar_dataset.cli.data import main

    status = main([str(a) for a in args])
    captured = capsys.readouterr()
    return status, captured.out, captured.err


def digest(root: pathlib.Path) -> str:
    h = hashlib.sha256()
    for path in sorted(root.rglob("*")):
        h.update(str(path.relative_to(root)).encode())
        if path.is_file():
            h.update(path.read_bytes())
            h.update(str(path.stat().st_mtime_ns).encode())
    return h.hexdigest()


@pytest.fixture(scope="module", params=["2020", "2021"])
def imported(request, tmp_path_factory):
    root = tmp_path_factory.mktemp(f"release{request.param}")
    src = root / "release"
    truth = build_release(src, request.param, gzip_lidar=request.param == "2021")
    before = digest(src)
    from zendar_dataset.cli.data import main

    status = main(["import-release", str(src), str(root / "out"), "--split", "val"])
    assert status == 0
    assert digest(src) == before, "the release folder was modified"
    return request.param, src, root / "out", truth


def test_imported_dataset_validates(imported, capsys):
    _, _, out, _ = imported
    assert validate_dataset(out) == []
    status, stdout, _ = run("validate", out, capsys=capsys)
    assert status == 0, stdout


def test_imported_dataset_loads_in_zendar_dataset(imported):
    _, _, out, _ = imported
    from zendar_dataset import ZendarDataset

    ds = ZendarDataset(out, split="val", streams=("sar", "tracklog", "lidar"), reference="sar")
    assert len(ds) == 20
    item = ds[3]
    assert item["frame_id"].startswith("2020-02-03_2252_001/")
    assert item["lidar"] is not None and item["sar"]["left"]["image"].shape == (ROWS, COLS)
    # Radar cubes exist for the first 0.2 s only: those SAR frames get one.
    radar = ZendarDataset(out, split="val", streams=("radar", "sar"), reference="sar")
    assert len(radar) == 3 and radar[1]["radar"]["left"]["cube"].shape == (1, 16, 8, 4)


def test_streams_names_and_summary(imported):
    generation, _, out, truth = imported
    summary = json.loads((out / "release_import.json").read_text())
    (scene,) = summary["scenes"]
    kinds = {s["path"]: s["kind"] for s in scene["streams"]}
    base = "2020-02-03_2252/001/"
    assert kinds[base + "1739000J1Q_images.pbs"] == f"Image ({generation})"
    assert kinds[base + "1739000J2R_points.pbs"] == f"TrackerState ({generation})"
    assert kinds[base + "lidar/00/stream.pbs"] == "LidarPointsFrame (2020)"
    framing = {s["path"]: s["framing"] for s in scene["streams"]}
    assert framing[base + "lidar/00/stream.pbs"].startswith("no header" + (", gzip" if generation == "2021" else ""))
    assert framing[base + "vn200.pbs"].startswith("8-byte header")
    text = " | ".join(scene["assumptions"])
    assert "serial 1739000J1Q -> 'left'" in text and "serial 1739000J2R -> 'right'" in text
    assert "pixel (i, j) is flat element j*rows + i (the SDK viewer's reading): checked" in text
    index = open_dataset(out)
    reader = index.open_scene("2020-02-03_2252_001")
    assert set(reader.sensors("sar")) == set(SERIALS.values())
    assert reader.sensors("radar") == ["left"]


def test_sar_pixels_land_at_origin_plus_i_di_plus_j_dj(imported):
    generation, _, out, truth = imported
    reader = open_dataset(out).open_scene("2020-02-03_2252_001")
    for side, frames in truth.sar.items():
        times = reader.array(f"sar/{side}/timestamp_ns")[:]
        origin = reader.array(f"sar/{side}/origin_ecef")[:]
        di, dj = reader.array(f"sar/{side}/di_ecef")[:], reader.array(f"sar/{side}/dj_ecef")[:]
        images = reader.array(f"sar/{side}/image")
        assert images.shape == (len(frames), ROWS, COLS)
        for m, frame in enumerate(frames):
            assert times[m] == gps_seconds_to_ns(frame.timestamp_s)
            np.testing.assert_array_equal(origin[m], frame.origin_ecef)
            i, j = frame.bright_ij
            # The stored model puts the bright pixel exactly at the target's ECEF position.
            np.testing.assert_allclose(origin[m] + i * di[m] + j * dj[m], frame.target_ecef, atol=1e-6)
            image = np.abs(images[m])
            assert np.unravel_index(np.argmax(image), image.shape) == (i, j)
        store = stores.open_store(out / "scenes" / "2020-02-03_2252_001.zarr")
        try:
            attrs = stores.read_attrs(stores.get_node(store.root, f"sar/{side}"))
        finally:
            store.close()
        assert attrs["magnitude_only"] is (generation == "2020") and attrs["serial"] in SERIALS


def _bright_pixel_at(reader, side, timestamp_ns, points_ecef):
    times = reader.array(f"sar/{side}/timestamp_ns")[:]
    m = int(np.searchsorted(times, timestamp_ns))
    assert times[m] == timestamp_ns
    i, j, distance = ecef_to_sar_pixel(
        points_ecef, reader.array(f"sar/{side}/origin_ecef")[m], reader.array(f"sar/{side}/di_ecef")[m], reader.array(f"sar/{side}/dj_ecef")[m]
    )
    image = np.abs(reader.array(f"sar/{side}/image")[m])
    return image[np.rint(i).astype(int), np.rint(j).astype(int)], image, distance


def test_lidar_and_detection_ecef_positions_land_on_the_bright_pixel(imported):
    _, _, out, truth = imported
    reader = open_dataset(out).open_scene("2020-02-03_2252_001")
    # Lidar: the first point of each sweep is the target seen by the left radar.
    offsets = reader.array("lidar/lidar_00/offsets")[:]
    position_ecef = reader.array("lidar/lidar_00/position_ecef")[:]
    for m, frame in enumerate(truth.sar["left"]):
        value, image, distance = _bright_pixel_at(reader, "left", gps_seconds_to_ns(frame.timestamp_s), position_ecef[offsets[m]])
        assert value == image.max() and distance < 1e-6
    # Detections: the first of each frame is that radar's target.
    for side, frames in truth.sar.items():
        d_offsets = reader.array(f"detections/{side}/offsets")[:]
        d_ecef = reader.array(f"detections/{side}/position_ecef")[:]
        d_times = reader.array(f"detections/{side}/timestamp_ns")[:]
        assert d_offsets[-1] == truth.n_detections[side]
        for m, frame in enumerate(frames):
            assert d_times[m] == gps_seconds_to_ns(frame.timestamp_s)
            value, image, _ = _bright_pixel_at(reader, side, d_times[m], d_ecef[d_offsets[m]])
            assert value == image.max()
        ranges = reader.array(f"detections/{side}/range_m")[:]
        assert ranges[0] == np.float32(10.5) and np.isnan(ranges).sum() == 1  # the NaN detection is kept as NaN


def test_tracklog_cubes_and_camera_index(imported):
    _, src, out, truth = imported
    reader = open_dataset(out).open_scene("2020-02-03_2252_001")
    t = reader.array("tracklog/timestamp_ns")[:]
    assert t.tolist() == [gps_seconds_to_ns(s) for s in truth.tracklog_s]
    # The column-wise tracklog equals the record-by-record decode of the same file.
    records = list(iter_messages(src / "2020-02-03_2252" / "001" / "vn200.pbs"))
    np.testing.assert_array_equal(reader.array("tracklog/position_ecef")[:], [[r["position"][a] for a in "xyz"] for r in records])
    q = np.array([[r["attitude"][a] for a in "wxyz"] for r in records])
    np.testing.assert_allclose(reader.array("tracklog/attitude_wxyz")[:], q / np.linalg.norm(q, axis=1, keepdims=True), rtol=0, atol=1e-15)
    cube = reader.array("radar/left/cube")[2]
    assert cube.shape == (16, 8, 4) and np.argwhere(np.abs(cube[..., 0]) > 0).tolist() == [[5, 5]]
    assert reader.calibration.radar("left").range_bin_m == pytest.approx(0.176)
    index = reader.array("camera_index/camera/frame_index")[:]
    assert index.tolist() == list(range(30))


def test_rerun_resumes_without_touching_finished_scenes(imported, capsys):
    _, src, out, _ = imported
    before = digest(out / "scenes")
    status, stdout, _ = run("import-release", src, out, "--split", "val", capsys=capsys)
    assert status == 0 and "already imported" in stdout
    assert digest(out / "scenes") == before


def test_truncated_stream_exit_2_one_line_then_skip_corrupt(tmp_path, capsys):
    src = tmp_path / "release"
    build_release(src)
    images = src / "2020-02-03_2252" / "001" / "1739000J1Q_images.pbs"
    data = images.read_bytes()
    images.write_bytes(data[:-100])
    status, _, err = run("import-release", src, tmp_path / "out", capsys=capsys)
    assert status == 2
    assert "1739000J1Q_images.pbs: byte offset" in err and "only" in err and "Traceback" not in err
    assert not (tmp_path / "out" / "scenes" / "2020-02-03_2252_001.zarr").exists()
    status, stdout, _ = run("import-release", src, tmp_path / "out", "--skip-corrupt", capsys=capsys)
    assert status == 0 and "lost" in stdout
    assert validate_dataset(tmp_path / "out") == []


def test_output_inside_source_is_refused(tmp_path, capsys):
    src = tmp_path / "release"
    enc.write_stream(src / "vn200.pbs", [enc.position_record(T0_S, (1, 0, 0, 0), (6.4e6, 0, 0), 0)])
    status, _, err = run("import-release", src, src / "out", capsys=capsys)
    assert status == 2 and "outside the release folder" in err
    assert sorted(p.name for p in src.iterdir()) == ["vn200.pbs"]


def test_row_major_pixels_are_detected_from_known_points(tmp_path, capsys):
    src = tmp_path / "release"
    truth = build_release(src, row_major=True)
    status, stdout, _ = run("import-release", src, tmp_path / "out", capsys=capsys)
    assert status == 0
    assert "i*cols + j (row-major, NOT the SDK viewer's reading): checked" in stdout
    reader = open_dataset(tmp_path / "out").open_scene("2020-02-03_2252_001")
    for m, frame in enumerate(truth.sar["right"][:5]):
        image = np.abs(reader.array("sar/right/image")[m])
        assert np.unravel_index(np.argmax(image), image.shape) == frame.bright_ij


def test_validate_catches_detection_arrays_of_different_lengths(imported, tmp_path):
    from tests.format.helpers import replace_array

    _, _, out, _ = imported
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    store = copy / "scenes" / "2020-02-03_2252_001.zarr"
    replace_array(store, "detections/left/snr", np.ones(5, np.float32))
    replace_array(store, "detections/right/position_ecef", np.full((40, 3), np.nan))  # NaN allowed, 40 of 41 rows not
    problems = validate_dataset(copy)
    assert any("detections/left: expected every per-detection array to have the same rows" in p for p in problems)
    assert any("detections/right" in p and "'position_ecef': 40" in p for p in problems)
    assert not any("NaN" in p for p in problems)


def test_hdf5_backend(tmp_path, capsys):
    src = tmp_path / "release"
    build_release(src, "2021")
    status, _, err = run("import-release", src, tmp_path / "out", "--backend", "hdf5", "--scene-id", "drive-1", capsys=capsys)
    assert status == 0, err
    assert (tmp_path / "out" / "scenes" / "drive-1.h5").is_file()
    assert validate_dataset(tmp_path / "out") == []
    reader = open_dataset(tmp_path / "out").open_scene("drive-1")
    assert reader.array("detections/left/position_ecef").shape == (41, 3)


def test_ctrl_c_leaves_no_half_scene(tmp_path, capsys, monkeypatch):
    from zendar_dataset.format.writer import SceneWriter

    src = tmp_path / "release"
    build_release(src)
    real = SceneWriter.append_lidar
    calls = {"n": 0}

    def interrupted(self, *args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 5:  # mid-way through the scene, SAR and radar already written
            raise KeyboardInterrupt
        return real(self, *args, **kwargs)

    monkeypatch.setattr(SceneWriter, "append_lidar", interrupted)
    status, _, err = run("import-release", src, tmp_path / "out", capsys=capsys)
    assert status == 130 and "Traceback" not in err
    leftovers = list((tmp_path / "out" / "scenes").iterdir()) if (tmp_path / "out" / "scenes").exists() else []
    assert leftovers == []
    monkeypatch.setattr(SceneWriter, "append_lidar", real)
    status, _, _ = run("import-release", src, tmp_path / "out", capsys=capsys)
    assert status == 0 and validate_dataset(tmp_path / "out") == []


def test_disk_full_exits_1_with_the_path(tmp_path, capsys, monkeypatch):
    import errno

    from zendar_dataset.format.writer import SceneWriter

    src = tmp_path / "release"
    build_release(src)

    def full(self, *args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device", str(self.path))

    monkeypatch.setattr(SceneWriter, "append_sar", full)
    status, _, err = run("import-release", src, tmp_path / "out", capsys=capsys)
    assert status == 1
    assert err.strip().splitlines()[-1] == f"error: {tmp_path / 'out' / 'scenes' / '2020-02-03_2252_001.zarr'}: No space left on device"
    assert list((tmp_path / "out" / "scenes").iterdir()) == []


def test_single_message_model_raw_packets_and_unknown_streams(tmp_path, capsys):
    src = tmp_path / "release"
    build_release(src)
    scene = src / "2020-02-03_2252" / "001"
    # The range-Doppler model as a bare *.pb message (no length prefix, no header).
    model = enc.rd_model(4, (0.0, 0.176, 16), (-0.4, 0.1, 8), [(0.0019 * a, 0.0, 0.0) for a in range(4)], 0.0039)
    (scene / "range_Doppler" / "left_model.pbs").unlink()
    (scene / "range_Doppler" / "left_model.pb").write_bytes(model)
    words = np.arange(8, dtype=np.uint32)
    enc.write_stream(scene / "radar" / "front" / "stream.pbs", [enc.chirp_response(T0_S + k * 1e-4, words, 0, -1) for k in range(3)], header=False)
    enc.write_stream(scene / "misc.pbs", [enc.f64(7, 1.0) + enc.uvar(9, 3)] * 2)  # a message no schema defines
    status, stdout, _ = run("import-release", src, tmp_path / "out", capsys=capsys)
    assert status == 0
    assert "range_Doppler/left_model.pb: RangeDopplerImageModel (2020), 1 records -> calibration/left" in stdout
    assert "radar/front/stream.pbs: ChirpResponse (raw)" in stdout and "raw acquisition packets are not converted" in stdout
    assert "misc.pbs: ?" in stdout and "no known message decodes it" in stdout
    reader = open_dataset(tmp_path / "out").open_scene("2020-02-03_2252_001")
    assert reader.array("radar/left/cube").shape == (5, 16, 8, 4)
    assert reader.sensors("radar") == ["left"]


def test_paper_sized_cubes_without_a_model_take_the_paper_layout(tmp_path, capsys):
    src = tmp_path / "release"
    cube = np.zeros((512, 256, 4), np.complex64)
    cube[100, 128 + 7, :] = [1, 1j, -1, -1j]
    enc.write_stream(src / "range_Doppler" / "right_rd.pbs", [enc.rd_frame(T0_S + k * 0.05, cube) for k in range(2)])
    status, stdout, _ = run("import-release", src, tmp_path / "out", capsys=capsys)
    assert status == 0 and "the paper's cube layout is assumed" in stdout
    reader = open_dataset(tmp_path / "out").open_scene("release")
    stored = reader.array("radar/right/cube")[1]
    np.testing.assert_array_equal(stored, cube)
    calibration = reader.calibration.radar("right")
    assert calibration.rx_positions_m.shape == (4, 3) and calibration.range_bin_m == pytest.approx(0.176)
    assert validate_dataset(tmp_path / "out") == []


def test_sar_frames_of_another_shape_are_skipped_and_counted(tmp_path):
    from zendar_dataset.release import import_release

    attitude, position = (0.5, -0.5, 0.5, -0.5), (-2.7e6, -4.26e6, 3.88e6)
    origin = (position[0] + 1.0, position[1], position[2])
    records = [
        enc.image_2020(T0_S + k / 10, attitude, position, k, origin, (0.04, 0, 0), (0, 0.04, 0), rows, 6, bytes(4 * 6 * rows))
        for k, rows in enumerate((4, 5, 4))
    ]
    enc.write_stream(tmp_path / "src" / "X_images.pbs", records)
    summary = import_release(tmp_path / "src", tmp_path / "out")
    assert "    skipped: 1 frames: shape [5, 6] differs from the stream's first [4, 6]" in summary.lines()
    reader = open_dataset(tmp_path / "out").open_scene("src")
    (radar,) = reader.sensors("sar")  # serial X, or the side its images lie on
    assert reader.array(f"sar/{radar}/image").shape == (2, 4, 6)


@pytest.mark.parametrize(
    "doppler_start, range_start, expected",
    [(-0.4, 0.0, "centred"), (0.0, 0.0, "fftshift"), (0.0, 1.5, "skipped"), (0.13, 0.0, "skipped")],
)
def test_doppler_axis_conventions(tmp_path, capsys, doppler_start, range_start, expected):
    src = tmp_path / "release"
    cube = (np.arange(6 * 8 * 2) + 1j).astype(np.complex64).reshape(6, 8, 2)
    enc.write_stream(src / "left_model.pbs", [enc.rd_model(2, (range_start, 0.2, 6), (doppler_start, 0.1, 8), [(0, 0, 0), (0.002, 0, 0)], 0.0039)])
    enc.write_stream(src / "left_rd.pbs", [enc.rd_frame(T0_S, cube)])
    status, stdout, _ = run("import-release", src, tmp_path / "out", capsys=capsys)
    assert status == 0
    scene = open_dataset(tmp_path / "out").open_scene("release")
    if expected == "skipped":
        assert "radar" not in {s.split("/")[0] for s in scene.streams} and ("range axis starts" in stdout or "neither centred" in stdout)
        return
    stored = scene.array("radar/left/cube")[0]
    np.testing.assert_array_equal(stored, cube if expected == "centred" else np.fft.fftshift(cube, axes=1))
    # Format v1 puts zero velocity in bin D/2 = 4: the release's bin whose velocity is 0 m/s lands there.
    zero_velocity_bin = int(round(-doppler_start / 0.1))  # start + k * delta == 0
    np.testing.assert_array_equal(stored[:, 4], cube[:, zero_velocity_bin])


@pytest.mark.parametrize("skip_corrupt", [False, True])
def test_headerless_stream_of_unknown_messages_is_skipped_not_an_error(tmp_path, capsys, skip_corrupt):
    src = tmp_path / "release"
    build_release(src)
    scene = src / "2020-02-03_2252" / "001"
    enc.write_stream(scene / "index" / "stream.pbs", [enc.time_index(T0_S + k, 4096 * k) for k in range(6)], header=False)
    flags = ["--skip-corrupt"] if skip_corrupt else []
    status, stdout, err = run("import-release", src, tmp_path / "out", *flags, capsys=capsys)
    assert status == 0, err
    (line,) = [l for l in stdout.splitlines() if l.startswith("  2020-02-03_2252/001/index/stream.pbs")]
    assert line.startswith("  2020-02-03_2252/001/index/stream.pbs: ?, 0 records")
    after = stdout.split(line, 1)[1]
    assert "no known message decodes it" in after.splitlines()[1] and "first mismatch" in after.splitlines()[1]
    assert "lost" not in after.split("\n  20")[0]
    reader = open_dataset(tmp_path / "out").open_scene("2020-02-03_2252_001")
    assert set(reader.sensors("sar")) == {"left", "right"}


def test_camera_named_after_its_folder_apart_from_radars_and_pixel_evidence_in_db(tmp_path, capsys):
    import re

    src = tmp_path / "release"
    build_release(src)
    scene = src / "2020-02-03_2252" / "001"
    (scene / "camera" / "left").mkdir()
    (scene / "camera" / "index.pbs").rename(scene / "camera" / "left" / "index.pbs")
    status, stdout, err = run("import-release", src, tmp_path / "out", capsys=capsys)
    assert status == 0, err
    reader = open_dataset(tmp_path / "out").open_scene("2020-02-03_2252_001")
    assert "camera_index/camera_left" in reader.streams and "radar/left" in reader.streams
    assert reader.array("camera_index/camera_left/frame_index")[:].tolist() == list(range(30))
    evidence = [line for line in stdout.splitlines() if "pixel (i, j) is flat element" in line]
    assert len(evidence) == 2
    for line in evidence:
        # One bright pixel per frame against a background of 0-9: capped, not "3.45e+73x".
        assert re.search(r"checked, \d+ known points in \d+ frames: (> \+60|[+-]\d+\.\d) dB brighter", line), line
        assert "e+" not in line


def _read_ahead_threads() -> list:
    import threading

    return [t for t in threading.enumerate() if t.name == "zendar-read-ahead"]


def test_a_lidar_record_that_does_not_decode_stops_the_scene_or_is_skipped(tmp_path, capsys):
    """The lidar is decoded on a thread from the start of the scene: its error still names the record, the
    scene is not written, and no decoding thread is left behind; with --skip-corrupt the sweep is lost."""
    from zendar_dataset.release import ReleaseStream

    src = tmp_path / "release"
    build_release(src)
    lidar = src / "2020-02-03_2252" / "001" / "lidar" / "00" / "stream.pbs"
    with ReleaseStream(lidar) as stream:
        records = [bytes(buf[start:end]) for _, buf, start, end in stream.records()]
    # A third sweep with one more point whose only field is a tag without its value: it frames, it does not decode.
    records[2] += b"\x12\x01\x08"
    enc.write_stream(lidar, records, header=False)
    bad_offset = sum(4 + len(r) for r in records[:2])
    status, _, err = run("import-release", src, tmp_path / "out", capsys=capsys)
    assert status == 2 and "Traceback" not in err
    assert f"stream.pbs: byte offset {bad_offset}" in err and "does not decode" in err
    assert list((tmp_path / "out" / "scenes").iterdir()) == []
    assert _read_ahead_threads() == []
    status, stdout, err = run("import-release", src, tmp_path / "out", "--skip-corrupt", capsys=capsys)
    assert status == 0, err
    assert f"{4 + len(records[2])} bytes at offset {bad_offset}" in stdout
    reader = open_dataset(tmp_path / "out").open_scene("2020-02-03_2252_001")
    assert reader.array("lidar/lidar_00/timestamp_ns").shape[0] == len(records) - 1
    assert validate_dataset(tmp_path / "out") == []


def test_a_failure_before_the_lidar_is_written_leaves_no_decoding_thread(tmp_path, capsys, monkeypatch):
    from zendar_dataset.format.writer import SceneWriter

    src = tmp_path / "release"
    build_release(src)

    def failing(self, *args, **kwargs):
        raise OSError("the cube writer failed")

    monkeypatch.setattr(SceneWriter, "append_radar", failing)  # after the images, before the lidar
    status, _, err = run("import-release", src, tmp_path / "out", capsys=capsys)
    assert status != 0 and "the cube writer failed" in err
    assert _read_ahead_threads() == []
