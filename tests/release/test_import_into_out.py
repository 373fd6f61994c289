"""What an import finds in SRC and leaves in OUT: clashing scene ids, linked folders, empty streams,
an earlier import's dataset (other backend, name, scenes outside splits, summary), nothing written on
exit 2, every problem at once."""

from __future__ import annotations

import json
import os

import pytest

from tests.release import encoder as enc
from tests.release.fixture import T0_S, build_release
from tests.release.test_import import run
from zendar_dataset.format import open_dataset


def _tracklog_scene(folder, t0_s: float) -> None:
    enc.write_stream(folder / "vn200.pbs", [enc.position_record(t0_s + k * 0.01, (1, 0, 0, 0), (6.4e6, 0, 0), k) for k in range(5)])


def _import(capsys, *args):
    status, stdout, err = run("import-release", *args, capsys=capsys)
    assert "Traceback" not in err
    return status, stdout, err


def test_two_folders_giving_one_scene_id_are_an_error_naming_both(tmp_path, capsys):
    src = tmp_path / "release"
    _tracklog_scene(src / "a" / "2020-02-21_0900" / "001", T0_S)
    _tracklog_scene(src / "b" / "2020-02-21_0900" / "001", T0_S + 1000)
    _tracklog_scene(src / "2020-02-22_1015" / "002", T0_S + 2000)
    _tracklog_scene(src / "2020-02-22_1015_002", T0_S + 3000)  # the flattened form of the same id
    out = tmp_path / "out"
    status, _, err = _import(capsys, src, out)
    assert status == 2
    for folder in ("a/2020-02-21_0900/001", "b/2020-02-21_0900/001", "2020-02-22_1015/002", "2020-02-22_1015_002"):
        assert str(src / folder) in err
    assert "2020-02-21_0900_001" in err and "2020-02-22_1015_002" in err
    assert not out.exists()


def test_linked_scene_folders_are_imported_under_the_names_of_the_links(tmp_path, capsys):
    elsewhere = tmp_path / "disk2" / "plain"
    _tracklog_scene(elsewhere, T0_S + 86400)
    src = tmp_path / "release"
    _tracklog_scene(src / "2020-02-21_0900" / "001", T0_S)
    (src / "2020-02-22_1015").mkdir()
    os.symlink(elsewhere, src / "2020-02-22_1015" / "001")
    os.symlink(src, src / "2020-02-22_1015" / "loop")  # a link to a folder above: entered once
    out = tmp_path / "out"
    status, stdout, err = _import(capsys, src, out)
    assert status == 0, err
    assert sorted(open_dataset(out).scene_ids()) == ["2020-02-21_0900_001", "2020-02-22_1015_001"]
    status, stdout, err = _import(capsys, src / "2020-02-22_1015" / "001", tmp_path / "out2")
    assert status == 0, err
    assert "scene 2020-02-22_1015_001 (imported)" in stdout


@pytest.mark.parametrize("content", [b"", bytes(8), bytes(8) + bytes(4)], ids=["empty", "header only", "one empty record"])
def test_a_stream_with_no_record_is_skipped_and_makes_no_sensor(tmp_path, capsys, content):
    src = tmp_path / "release"
    build_release(src, "2020")
    assert _import(capsys, src, tmp_path / "clean")[0] == 0
    scene = src / "2020-02-03_2252" / "001"
    (scene / "lidar" / "01").mkdir(parents=True)
    (scene / "lidar" / "01" / "stream.pbs").write_bytes(content)
    (scene / "spare.pbs").write_bytes(content)
    out = tmp_path / "out"
    status, stdout, err = _import(capsys, src, out)
    assert status == 0, err
    assert stdout.count("skipped: empty:") == 2
    clean = open_dataset(tmp_path / "clean").open_scene("2020-02-03_2252_001")
    reader = open_dataset(out).open_scene("2020-02-03_2252_001")
    assert sorted(reader.calibration.sensors) == sorted(clean.calibration.sensors)
    assert sorted(reader.streams) == sorted(clean.streams)
    assert {"sar/left", "sar/right", "radar/left"} <= set(reader.streams)
    summary = json.loads((out / "release_import.json").read_text())
    streams = {s["path"]: s for s in summary["scenes"][0]["streams"]}
    assert streams["2020-02-03_2252/001/spare.pbs"]["framing"] is not None


def test_an_unknown_stream_reports_its_framing(tmp_path, capsys):
    src = tmp_path / "release"
    _tracklog_scene(src / "2020-02-21_0900" / "001", T0_S)
    index = [enc.time_index(T0_S + k, 1000 * k) for k in range(1, 5)]
    enc.write_stream(src / "2020-02-21_0900" / "001" / "index.pbs", index, header=True)
    status, stdout, err = _import(capsys, src, tmp_path / "out")
    assert status == 0, err
    line = next(line for line in stdout.splitlines() if "index.pbs" in line)
    assert "framing None" not in line and "8-byte header" in line


def test_a_later_import_keeps_the_earlier_dataset_as_it_is(tmp_path, capsys):
    src = tmp_path / "release"
    for k, date in enumerate(("2020-02-21_0900", "2020-02-22_1015", "2020-02-23_1100")):
        _tracklog_scene(src / date / "001", T0_S + 86400 * k)
    out = tmp_path / "out"
    assert _import(capsys, src / "2020-02-21_0900", out, "--backend", "hdf5")[0] == 0
    assert _import(capsys, src / "2020-02-22_1015", out, "--split", "val")[0] == 0
    document = json.loads((out / "dataset.json").read_text())
    document["name"] = "my-dataset"
    document["splits"]["val"] = []  # its owner takes the second scene out of every split
    (out / "dataset.json").write_text(json.dumps(document))

    status, _, err = _import(capsys, src / "2020-02-23_1100", out)
    assert status == 0, err
    document = json.loads((out / "dataset.json").read_text())
    assert document["name"] == "my-dataset"
    assert document["scenes"] == {
        "2020-02-21_0900_001": {"path": "scenes/2020-02-21_0900_001.h5"},
        "2020-02-22_1015_001": {"path": "scenes/2020-02-22_1015_001.zarr"},
        "2020-02-23_1100_001": {"path": "scenes/2020-02-23_1100_001.zarr"},
    }
    assert document["splits"]["train"] == ["2020-02-21_0900_001", "2020-02-23_1100_001"]
    assert document["splits"]["val"] == []
    assert _import(capsys, src / "2020-02-21_0900", out)[1].count("(already imported)") == 1
    assert sorted(p.name for p in (out / "scenes").iterdir()) == [
        "2020-02-21_0900_001.h5", "2020-02-22_1015_001.zarr", "2020-02-23_1100_001.zarr"]
    assert open_dataset(out).open_scene("2020-02-21_0900_001").timestamps("tracklog").size == 5


def test_a_scene_listed_without_its_store_stops_the_import_before_anything_is_written(tmp_path, capsys):
    src = tmp_path / "release"
    _tracklog_scene(src / "2020-02-21_0900" / "001", T0_S)
    _tracklog_scene(src / "2020-02-22_1015" / "001", T0_S + 86400)
    out = tmp_path / "out"
    assert _import(capsys, src / "2020-02-21_0900", out)[0] == 0
    document = json.loads((out / "dataset.json").read_text())
    document["scenes"]["ghost"] = {"path": "scenes/ghost.zarr"}
    document["splits"]["test"] = ["ghost"]
    (out / "dataset.json").write_text(json.dumps(document))
    status, _, err = _import(capsys, src / "2020-02-22_1015", out)
    assert status == 2
    assert "'ghost'" in err and "scenes/ghost.zarr" in err
    assert sorted(p.name for p in (out / "scenes").iterdir()) == ["2020-02-21_0900_001.zarr"]


def test_the_summary_of_an_earlier_run_is_kept(tmp_path, capsys):
    src = tmp_path / "release"
    build_release(src, "2020")
    _tracklog_scene(src / "2020-02-24_0800" / "001", T0_S + 86400)
    out = tmp_path / "out"
    assert _import(capsys, src / "2020-02-03_2252", out)[0] == 0
    first = json.loads((out / "release_import.json").read_text())["scenes"][0]
    assert first["status"] == "imported" and len(first["streams"]) > 3

    status, stdout, err = _import(capsys, src, out)
    assert status == 0, err
    assert "scene 2020-02-03_2252_001 (already imported)" in stdout
    scenes = {s["scene_id"]: s for s in json.loads((out / "release_import.json").read_text())["scenes"]}
    assert scenes["2020-02-03_2252_001"] == first
    assert scenes["2020-02-24_0800_001"]["status"] == "imported"


def test_the_same_sides_command_run_again_resumes(tmp_path, capsys):
    src = tmp_path / "release"
    build_release(src, "2020")
    serial = next(p.name.split("_")[0] for p in (src / "2020-02-03_2252" / "001").glob("*_images.pbs"))
    out = tmp_path / "out"
    for _ in range(2):
        status, stdout, err = _import(capsys, src, out, "--sides", f"{serial}=left")
        assert status == 0, err
    assert "(already imported)" in stdout


def test_exit_2_writes_nothing_and_lists_every_problem(tmp_path, capsys):
    src = tmp_path / "release"
    build_release(src, "2020")
    lidar = src / "2020-02-03_2252" / "001" / "lidar" / "00" / "stream.pbs"
    lidar.write_bytes(lidar.read_bytes()[:-5])
    out = tmp_path / "out"
    status, _, err = _import(capsys, src, out, "--sides", "NOSUCHSERIAL=left")
    assert status == 2
    assert "stream.pbs" in err and "byte offset" in err and "NOSUCHSERIAL" in err
    assert not out.exists()


@pytest.mark.parametrize("split", ["", "a/b", "x y", ".hidden"])
def test_a_split_name_that_cannot_be_one_is_refused(tmp_path, capsys, split):
    src = tmp_path / "release"
    _tracklog_scene(src / "2020-02-21_0900" / "001", T0_S)
    status, _, err = _import(capsys, src, tmp_path / "out", "--split", split)
    assert status == 2 and "--split" in err
    assert not (tmp_path / "out").exists()


def test_a_truncated_stream_does_not_hide_the_sides_disagreement(tmp_path, capsys):
    from tests.release.test_sdk_roundtrip import _write_release

    src = tmp_path / "release"
    _write_release(src, "2020", flu_attitude=True)
    lidar = src / "2020-02-03_2252" / "001" / "lidar" / "00" / "stream.pbs"
    lidar.write_bytes(lidar.read_bytes()[:-5])
    status, _, err = _import(capsys, src, tmp_path / "out")
    assert status == 2
    assert "byte offset" in err and "left and right are not guessed" in err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("foreign", ["notes.txt", "release_import.json"])
def test_an_out_holding_files_of_its_own_is_refused_and_left_as_it_is(tmp_path, capsys, foreign):
    src = tmp_path / "release"
    _tracklog_scene(src / "2020-02-21_0900" / "001", T0_S)
    out = tmp_path / "out"
    if foreign == "release_import.json":
        (out / "scenes").mkdir(parents=True)  # an earlier import's folder, with somebody's file in it
    else:
        out.mkdir()
    (out / foreign).write_text("my precious notes")
    status, _, err = _import(capsys, src, out)
    assert status == 2 and foreign in err
    assert (out / foreign).read_text() == "my precious notes"
    assert not (out / "dataset.json").exists()


def test_an_out_that_is_a_file_is_refused(tmp_path, capsys):
    src = tmp_path / "release"
    _tracklog_scene(src / "2020-02-21_0900" / "001", T0_S)
    out = tmp_path / "out"
    out.write_text("mine")
    status, _, err = _import(capsys, src, out)
    assert status == 2 and "OUT is a file" in err
    assert out.read_text() == "mine"


def test_sides_of_serials_named_only_by_their_streams_resume_too(tmp_path, capsys):
    src = tmp_path / "release"
    build_release(src, "2020")
    scene = src / "2020-02-03_2252" / "001"
    serials = sorted(p.name.split("_")[0] for p in scene.glob("*_images.pbs"))
    for serial in serials:  # images named by the serial alone, no detections
        (scene / f"{serial}_images.pbs").rename(scene / f"{serial}.pbs")
        (scene / f"{serial}_points.pbs").unlink(missing_ok=True)
    sides = f"--sides={serials[0]}=left,{serials[1]}=right"
    for _ in range(2):
        status, stdout, err = _import(capsys, src, tmp_path / "out", sides)
        assert status == 0, err
    assert "(already imported)" in stdout


def test_a_scene_id_that_cannot_name_a_store_is_refused_before_out_exists(tmp_path, capsys):
    src = tmp_path / "release"
    _tracklog_scene(src / "2020-02-21_0900" / "001", T0_S)
    status, _, err = _import(capsys, src, tmp_path / "out", "--scene-id", "a/b")
    assert status == 2 and "a/b" in err
    assert not (tmp_path / "out").exists()


def test_a_split_name_with_a_trailing_newline_is_refused(tmp_path, capsys):
    src = tmp_path / "release"
    _tracklog_scene(src / "2020-02-21_0900" / "001", T0_S)
    status, _, err = _import(capsys, src, tmp_path / "out", "--split", "val\n")
    assert status == 2 and "--split" in err
