"""The zendar-data subcommands of format v1, run through the real entry point."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

import numpy as np
import pytest

from tests.format.conftest import make_dataset, tree_digest
from tests.format.helpers import dump, replace_array, set_attr
from zendar_dataset.format import open_dataset
from zendar_dataset.format.ground_truth import ground_truth_frames


def zendar_data(*args: str) -> subprocess.CompletedProcess:
    executable = shutil.which("zendar-data")
    command = [executable] if executable else [sys.executable, "-m", "zendar_dataset.cli.data"]
    return subprocess.run([*command, *map(str, args)], capture_output=True, text=True, timeout=300)


def in_process(*args: str, capsys) -> tuple[int, str, str]:
    """The same entry point, called in this process (cheaper than a subprocess)."""
    from zendar_dataset.cli.data import main

    status = main([str(a) for a in args])
    captured = capsys.readouterr()
    return status, captured.out, captured.err


def test_validate_passes_on_written_dataset(dataset_root):
    result = zendar_data("validate", dataset_root)
    assert result.returncode == 0, result.stdout + result.stderr
    lines = result.stdout.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("ok:") and "4 scenes" in lines[0]


def test_validate_lists_every_violation(dataset_root, backend):
    suffix = ".zarr" if backend == "zarr" else ".h5"
    s0, s1 = (dataset_root / "scenes" / f"s{i}{suffix}" for i in (0, 1))
    replace_array(s0, "radar/right/cube", np.zeros((4, 16, 8, 4), np.complex128))  # dtype
    replace_array(s0, "lidar/top/offsets", np.array([0, 5, 3, 9, 10], np.int64))  # decreasing, wrong end
    replace_array(s1, "sar/left/di_ecef", None)  # missing
    replace_array(s1, "radar/left/timestamp_ns", np.array([4, 3, 5, 6], np.int64))  # order
    set_attr(s1, "", "time_reference", "utc")
    labels_t = np.array([1, 2], np.int64)
    replace_array(s1, "labels/moving_cars/timestamp_ns", labels_t)  # no such SAR frame
    document = json.loads((dataset_root / "dataset.json").read_text())
    document["splits"]["val"].append("s0")  # s0 in two splits
    (dataset_root / "dataset.json").write_text(json.dumps(document))
    result = zendar_data("validate", dataset_root)
    assert result.returncode == 2
    out = result.stdout
    expected = [
        "s0: radar/right/cube: expected dtype complex64, found complex128",
        "s0: lidar/top/offsets: expected non-decreasing offsets from 0 to",
        "s1: sar/left/di_ecef: expected an array [N, 3] float64, found nothing",
        "s1: radar/left/timestamp_ns: expected strictly increasing timestamps, found 3 at index 1 after 4",
        "s1: /: expected attribute time_reference 'gps', found 'utc'",
        "s1: labels/moving_cars/timestamp_ns: expected timestamps of sar/left frames",
        "expected each scene in one split, found 's0' in ['train', 'val']",
    ]
    for fragment in expected:
        assert fragment in out, fragment
    assert len(out.strip().splitlines()) == len(expected)
    assert "Traceback" not in result.stderr and "7 format violation" in result.stderr


def test_validate_finds_missing_and_corrupt_chunks(tmp_path):
    dataset_root = make_dataset(tmp_path / "ds", "zarr")
    scene = dataset_root / "scenes" / "s2.zarr"
    (scene / "sar/right/image/c/1/0/0").unlink()
    chunk = scene / "camera/front/image/c/0/0/0/0"
    chunk.write_bytes(chunk.read_bytes()[:5])
    result = zendar_data("validate", dataset_root)
    assert result.returncode == 2
    assert result.stdout.splitlines() == [
        "s2: sar/right/image: expected every chunk stored (the store records checksums), found 1 missing: chunk [1, 0, 0]",
        "s2: camera/front/image: chunk [0, 0, 0, 0]: expected a readable chunk (rows 0:1), found a truncated "
        "or corrupt one (RuntimeError: error during blosc decompression: -1)",
    ]


@pytest.mark.slow
def test_convert_round_trip_is_lossless_and_reads_only(tmp_path, capsys):
    source = make_dataset(tmp_path / "zarr", "zarr", seed=3)
    before = tree_digest(source)
    assert zendar_data("convert", source, tmp_path / "h5", "--to", "hdf5").returncode == 0
    assert in_process("convert", tmp_path / "h5", tmp_path / "back", "--to", "zarr", capsys=capsys)[0] == 0
    assert tree_digest(source) == before
    for scene_id in ("s0", "s1", "s2", "s3"):
        original = dump(source / "scenes" / f"{scene_id}.zarr")
        for converted in (tmp_path / "h5" / "scenes" / f"{scene_id}.h5", tmp_path / "back" / "scenes" / f"{scene_id}.zarr"):
            arrays, attrs = dump(converted)
            assert sorted(arrays) == sorted(original[0])
            for name, value in original[0].items():
                assert arrays[name].dtype == value.dtype and arrays[name].shape == value.shape, name
                assert arrays[name].tobytes() == value.tobytes(), name
            assert attrs == original[1]
    h5_index = open_dataset(tmp_path / "h5")
    assert h5_index.scenes["s0"] == "scenes/s0.h5" and h5_index.splits == open_dataset(source).splits
    assert h5_index.open_scene("s1").array("radar/left/cube").chunks == (1, 16, 8, 4)
    assert in_process("validate", tmp_path / "h5", capsys=capsys)[0] == 0


def test_convert_refuses_non_empty_output(tmp_path, capsys):
    source = make_dataset(tmp_path / "src", "hdf5")
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    status, _, err = in_process("convert", source, out, "--to", "zarr", capsys=capsys)
    assert status == 2 and "not an empty directory" in err
    assert [p.name for p in out.iterdir()] == ["keep.txt"]


@pytest.mark.slow
def test_export_gt_shape_and_empty_frames(dataset_root, tmp_path, capsys):
    before = tree_digest(dataset_root)
    out = tmp_path / "gt.json"
    result = zendar_data("export-gt", dataset_root, "--split", "train", "-o", out)
    assert result.returncode == 0, result.stderr
    document = json.loads(out.read_text())
    assert list(document) == ["frames"]
    frames = document["frames"]
    index = open_dataset(dataset_root)
    expected_ids = [f"{s}/{t}" for s in ("s0", "s1") for t in index.open_scene(s).timestamps("sar/left")]
    assert sorted(frames) == sorted(expected_ids)
    labels = index.open_scene("s0").labels()
    first = f"s0/{labels['timestamp_ns'][0]}"
    assert [car["track_id"] for car in frames[first]] == labels["track_id"].tolist()
    assert frames[first][1] == {name: labels[name][1].item() for name in ("x", "y", "length", "width", "yaw", "vx", "vy", "track_id")}
    empty = [frame for frame in expected_ids if frame != f"s0/{labels['timestamp_ns'][0]}" and not frame.startswith("s1/")]
    assert empty and all(frames[frame] == [] for frame in empty)
    assert sum(len(cars) for cars in frames.values()) == 4
    assert frames == ground_truth_frames(dataset_root, "train")
    # Refuses to replace the file, rejects an unknown split and a split whose labels are withheld.
    status, _, err = in_process("export-gt", dataset_root, "--split", "train", "-o", out, capsys=capsys)
    assert status == 2 and "exists already" in err
    status, _, err = in_process("export-gt", dataset_root, "--split", "dev", "-o", tmp_path / "x.json", capsys=capsys)
    assert status == 2 and "unknown split 'dev'" in err and "Traceback" not in err
    status, _, err = in_process("export-gt", dataset_root, "--split", "test", "-o", tmp_path / "y.json", capsys=capsys)
    assert status == 2 and "found none with labels/moving_cars" in err
    assert not (tmp_path / "x.json").exists() and not (tmp_path / "y.json").exists()
    assert in_process("validate", dataset_root, capsys=capsys)[0] == 0
    assert tree_digest(dataset_root) == before
