"""Tolerant where the SDK is tolerant: optional and oneof fields, unknown fields once the kind is decided."""

from __future__ import annotations

import json

import pytest

from tests.release import encoder as enc
from tests.release.fixture import build_release
from tests.release.sdk_messages import sdk
from tests.release.test_import import run
from zendar_dataset.format import open_dataset
from zendar_dataset.release import ReleaseStream

ATT = (0.5, -0.5, 0.5, -0.5)
POS = (-2_706_000.25, -4_261_000.5, 3_885_000.75)
SCENE = ("2020-02-03_2252", "001")


def _scene_summary(out) -> dict:
    (scene,) = json.loads((out / "release_import.json").read_text())["scenes"]
    return {s["path"].split("/", 2)[2]: s for s in scene["streams"]}


def _without(generation: str, name: str, record: bytes, field: str) -> bytes:
    """``record`` re-serialized by the SDK's definition of message ``name`` without ``field``."""
    message = sdk(generation)[name].FromString(record)
    message.ClearField(field)
    return message.SerializeToString()


@pytest.mark.parametrize("generation", ["2020", "2021"])
def test_an_image_without_its_optional_cartesian_is_skipped_and_counted(tmp_path, capsys, generation):
    src = tmp_path / "release"
    truth = build_release(src, generation)
    path = src.joinpath(*SCENE, "1739000J1Q_images.pbs")
    with ReleaseStream(path) as stream:
        records = [bytes(buf[start:end]) for _, buf, start, end in stream.records()]
    records[4] = _without(generation, "Image", records[4], "cartesian")
    if generation == "2021":
        records[6] = _without(generation, "Image", records[6], "meta")
    enc.write_stream(path, records)
    status, stdout, err = run("import-release", src, tmp_path / "out", capsys=capsys)
    assert status == 0, err
    skipped = _scene_summary(tmp_path / "out")["1739000J1Q_images.pbs"]["skipped"]
    assert any(s.startswith("1 records without Image.cartesian (optional in the SDK") for s in skipped), skipped
    reader = open_dataset(tmp_path / "out").open_scene("_".join(SCENE))
    expected = len(truth.sar["left"]) - (1 if generation == "2020" else 2)
    assert reader.array("sar/left/image").shape[0] == expected
    if generation == "2021":
        assert any(s.startswith("1 records without Image.meta") for s in skipped), skipped


def test_a_2021_tracker_state_without_meta_is_skipped_and_counted(tmp_path, capsys):
    src = tmp_path / "release"
    truth = build_release(src, "2021")
    path = src.joinpath(*SCENE, "1739000J2R_points.pbs")
    with ReleaseStream(path) as stream:
        records = [bytes(buf[start:end]) for _, buf, start, end in stream.records()]
    records[5] = _without("2021", "TrackerState", records[5], "meta")
    enc.write_stream(path, records)
    status, _, err = run("import-release", src, tmp_path / "out", capsys=capsys)
    assert status == 0, err
    skipped = _scene_summary(tmp_path / "out")["1739000J2R_points.pbs"]["skipped"]
    assert any(s.startswith("1 records without TrackerState.meta") for s in skipped), skipped
    reader = open_dataset(tmp_path / "out").open_scene("_".join(SCENE))
    assert reader.array("detections/right/timestamp_ns").shape[0] == len(truth.sar["right"]) - 1


def test_unknown_fields_after_the_kind_is_decided_are_counted_and_reported(tmp_path, capsys):
    src = tmp_path / "release"
    truth = build_release(src)
    images = src.joinpath(*SCENE, "1739000J1Q_images.pbs")
    points = src.joinpath(*SCENE, "1739000J1Q_points.pbs")
    with ReleaseStream(images) as stream:
        image_records = [bytes(buf[start:end]) for _, buf, start, end in stream.records()]
    # Records after the first carry a field 7 no definition has (the first decides the kind).
    image_records[1:] = [r + enc.uvar(7, 42) for r in image_records[1:]]
    enc.write_stream(images, image_records)
    detection = enc.point(truth.sar["left"][0].timestamp_s, truth.sar["left"][0].target_ecef, 1, 2, 3, 4, 5, 6)
    with ReleaseStream(points) as stream:
        point_records = [bytes(buf[start:end]) for _, buf, start, end in stream.records()]
    # A point with an unknown field 12 inside a later record: the element takes the generic path.
    point_records[2] += enc.ld(2, detection + enc.f32(12, 1.5))
    enc.write_stream(points, point_records)
    status, stdout, err = run("import-release", src, tmp_path / "out", capsys=capsys)
    assert status == 0, err
    streams = _scene_summary(tmp_path / "out")
    assert streams["1739000J1Q_images.pbs"]["unknown_fields"] == {"Image.7": len(image_records) - 1}
    assert streams["1739000J1Q_points.pbs"]["unknown_fields"] == {"Point.12": 1}
    assert f"unknown fields (not in the SDK's definition) ignored: Image.7 x{len(image_records) - 1}" in stdout
    reader = open_dataset(tmp_path / "out").open_scene("_".join(SCENE))
    assert reader.array("sar/left/image").shape[0] == len(image_records)
    assert reader.array("detections/left/offsets")[-1] == truth.n_detections["left"] + 1


def _pose_record(t: float, quality: bool) -> bytes:
    out = enc.ld(1, enc.time_record(t)) + enc.ld(2, enc.vec3(*POS)) + enc.ld(5, enc.quaternion(ATT))
    if quality:
        ins = enc.uvar(1, 2) + enc.uvar(2, 1) + enc.uvar(3, 0) + enc.uvar(4, 0) + enc.uvar(5, 0)
        pose_quality = enc.ld(1, enc.vec3(0.1, 0.1, 0.2)) + enc.f64(2, 0.05) + enc.uvar(3, 3) + enc.uvar(4, -1) + enc.ld(5, ins)
        out += enc.ld(8, pose_quality)
    return out


def test_raw_streams_decode_as_the_sdk_declares_them(tmp_path):
    # PoseRecord.pose_quality is a message of double, enum, int32 and sub-message fields;
    # ChirpResponse.rx0 is optional; LidarDataFrame requires mode and sensor_type, not a timestamp.
    cases = {
        "PoseRecord (raw)": [_pose_record(1.26e9 + k, quality=True) for k in range(3)],
        "ChirpResponse (raw)": [enc.ld(1, enc.time_record(1.26e9)) + enc.ld(3, enc.ld(3, bytes(16))) + enc.uvar(6, 1)] * 2,
        "LidarDataFrame (raw)": [
            enc.ld(2, enc.uvar(2, 0xEEFF) + enc.uvar(3, 3600) + enc.ld(4, enc.uvar(1, 900) + enc.uvar(2, 12))) + enc.uvar(3, 0x37) + enc.uvar(4, 0x22)
        ]
        * 2,
    }
    for label, records in cases.items():
        path = enc.write_stream(tmp_path / "stream.pbs", records, header=False)
        with ReleaseStream(path) as stream:
            assert stream.kind.label == label, stream.notes
            decoded = list(stream)
        if label == "PoseRecord (raw)":
            quality = decoded[0]["pose_quality"]
            assert quality["velocity_uncertainty"] == 0.05 and quality["number_of_satellites"] == -1
            assert quality["ins_status"]["mode"] == 2


def test_a_tracklog_without_quality_is_a_position_not_an_image_without_an_image(tmp_path):
    # 2020 Image's cartesian is optional, so a Position without quality decodes as both; the kind
    # whose records carry what it is converted from wins, whatever the file name says.
    records = [enc.f64(1, 1.26e9 + k) + enc.ld(2, enc.quaternion(ATT)) + enc.ld(3, enc.vec3(*POS)) + enc.uvar(4, k) for k in range(3)]
    path = enc.write_stream(tmp_path / "data.pbs", records)
    with ReleaseStream(path) as stream:
        assert stream.kind.label == "Position (2020)"
        assert "only Position (2020) carries the fields it is converted from" in stream.notes[0]
