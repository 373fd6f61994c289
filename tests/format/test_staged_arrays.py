"""Whole arrays written into a local zarr store through an in-memory stage are the files zarr itself
writes; groups already there keep their attributes; nothing already stored is overwritten. Lidar
points are written in batches of chunks and their ECEF positions compressed as the points are."""

from __future__ import annotations

import json
import pathlib
import shutil
import warnings

import numpy as np
import pytest
import zarr

from tests.format.conftest import ENU_ORIGIN, T0_NS, make_calibration, write_scene
from zendar_dataset.format import SceneWriter, stores
from zendar_dataset.format import writer as writer_module
from zendar_dataset.format.validate import validate_scene


def _tree(root: pathlib.Path) -> dict[str, object]:
    """Every file below ``root``: parsed JSON for metadata, bytes for chunks."""
    out: dict[str, object] = {}
    for path in sorted(root.rglob("*")):
        if path.is_file():
            key = str(path.relative_to(root))
            out[key] = json.loads(path.read_bytes()) if path.name == "zarr.json" else path.read_bytes()
    return out


def _arrays(rng: np.random.Generator) -> list[stores.NewArray]:
    ecef = np.array([-2_706_000.0, -4_261_000.0, 3_885_000.0]) + rng.normal(scale=20.0, size=(70_000, 3))
    return [
        stores.NewArray("sar/left/timestamp_ns", np.arange(5, dtype=np.int64) * 10**8, (5,), stores.SMALL, {"chunk_crc32c": "0"}),
        stores.NewArray("sar/left/origin_ecef", rng.normal(size=(5, 3)), (5, 3), stores.SMALL, {}),
        stores.NewArray("tracklog/attitude_wxyz", rng.normal(size=(9, 4)), (4, 4), stores.SMALL, {"note": [1, "a"]}),
        stores.NewArray("lidar/top/position_ecef", ecef, (65_536, 3), stores.FAST, {}),
        stores.NewArray("labels/moving_cars/x", np.zeros(0), (1,), stores.SMALL, {}),
    ]


def test_staged_arrays_are_the_files_zarr_writes(tmp_path):
    staged = stores.create_store(tmp_path / "staged.zarr", "zarr")
    reference = stores.create_store(tmp_path / "reference.zarr", "zarr")
    stores.write_arrays(staged.root, _arrays(np.random.default_rng(5)))
    arrays = _arrays(np.random.default_rng(5))
    stores.fill_arrays(stores.create_arrays(reference.root, arrays), arrays)  # zarr's own path, file by file
    written, expected = _tree(tmp_path / "staged.zarr"), _tree(tmp_path / "reference.zarr")
    assert written.keys() == expected.keys()
    for key in expected:
        assert written[key] == expected[key], key
    opened = zarr.open_group(str(tmp_path / "staged.zarr"), mode="r")
    np.testing.assert_array_equal(opened["lidar/top/position_ecef"][...], _arrays(np.random.default_rng(5))[3].data)
    assert opened["tracklog/attitude_wxyz"].attrs["note"] == [1, "a"]


def test_groups_already_there_keep_their_attributes(tmp_path):
    store = stores.create_store(tmp_path / "s.zarr", "zarr")
    stores.write_attrs(store.root.require_group("sar/left"), {"serial": "1739000J1Q"})
    stores.write_attrs(store.root, {"scene_id": "s0"})
    stores.write_arrays(store.root, [stores.NewArray("sar/left/origin_ecef", np.ones((2, 3)), (2, 3), stores.SMALL, {})])
    opened = zarr.open_group(str(tmp_path / "s.zarr"), mode="r")
    assert dict(opened["sar/left"].attrs) == {"serial": "1739000J1Q"}
    assert dict(opened.attrs) == {"scene_id": "s0"}
    np.testing.assert_array_equal(opened["sar/left/origin_ecef"][...], np.ones((2, 3)))


def test_an_array_already_stored_is_not_overwritten(tmp_path):
    store = stores.create_store(tmp_path / "s.zarr", "zarr")
    stores.write_arrays(store.root, [stores.NewArray("tracklog/timestamp_ns", np.arange(3), (3,), stores.SMALL, {})])
    with pytest.raises(FileExistsError, match="tracklog"):
        stores.write_arrays(store.root, [stores.NewArray("tracklog/timestamp_ns", np.zeros(7), (7,), stores.SMALL, {})])
    np.testing.assert_array_equal(zarr.open_array(str(tmp_path / "s.zarr/tracklog/timestamp_ns"), mode="r")[...], np.arange(3))


def test_a_file_where_a_chunk_folder_goes_is_an_error_naming_it(tmp_path):
    (tmp_path / "image" / "c").mkdir(parents=True)
    (tmp_path / "image" / "c" / "0").write_bytes(b"in the way")
    with pytest.raises(OSError, match="image/c/0"):
        stores.write_raw_frame(tmp_path / "image/c/0/0/0", np.zeros((2, 2), np.uint32), {tmp_path / "image"})


def test_array_kinds():
    assert stores.array_kind("radar/left/cube") == stores.RAW
    assert stores.array_kind("sar/right/image") == stores.RAW
    assert stores.array_kind("camera/front/image") == stores.FAST
    assert stores.array_kind("lidar/top/points") == stores.FAST
    assert stores.array_kind("lidar/top/position_ecef") == stores.FAST
    assert stores.array_kind("lidar/top/offsets") == stores.SMALL
    assert stores.array_kind("sar/left/origin_ecef") == stores.SMALL


@pytest.mark.parametrize("suffix", [".zarr", ".h5"])
def test_lidar_points_over_many_chunks_and_their_ecef_positions(tmp_path, suffix):
    rng = np.random.default_rng(11)
    rows = writer_module._LIDAR_FLUSH_ROWS + 3 * writer_module.LIDAR_CHUNK_ROWS + 123  # one batch, then the rest at close
    sizes = np.diff(np.linspace(0, rows, 9).astype(int))
    sweeps = [rng.normal(size=(n, 4)).astype(np.float32) for n in sizes]
    ecef = np.array([-2_706_000.0, -4_261_000.0, 3_885_000.0]) + rng.normal(size=(rows, 3))
    path = tmp_path / f"s{suffix}"
    with SceneWriter(path, "s0", enu_origin=ENU_ORIGIN, calibration=make_calibration()) as writer:
        for k, sweep in enumerate(sweeps):
            writer.append_lidar("top", T0_NS + k * 100_000_000, sweep)
        writer.write_extra_array("lidar/top/position_ecef", ecef)
    assert validate_scene(path, "s0") == []
    store = stores.open_store(path)
    try:
        points = store.root["lidar/top/points"]
        np.testing.assert_array_equal(points[...], np.concatenate(sweeps))
        np.testing.assert_array_equal(store.root["lidar/top/position_ecef"][...], ecef)
        np.testing.assert_array_equal(store.root["lidar/top/offsets"][...], np.concatenate([[0], np.cumsum(sizes)]))
        if suffix == ".zarr":
            assert stores.missing_chunks(points) == []
            codecs = [type(c).__name__ for c in store.root["lidar/top/position_ecef"].metadata.codecs]
            assert "BloscCodec" in codecs
    finally:
        store.close()


def test_an_array_is_not_stored_inside_another(tmp_path):
    store = stores.create_store(tmp_path / "s.zarr", "zarr")
    stores.write_arrays(store.root, [stores.NewArray("tracklog", np.arange(3), (3,), stores.SMALL, {})])
    with pytest.raises(FileExistsError, match="expected a group there"):
        stores.write_arrays(store.root, [stores.NewArray("tracklog/timestamp_ns", np.arange(3), (3,), stores.SMALL, {})])
    assert not (tmp_path / "s.zarr/tracklog/timestamp_ns").exists()  # refused before anything is written


def test_consolidated_metadata_is_zarrs_own(tmp_path):
    path = tmp_path / "s.zarr"
    with SceneWriter(path, "s0", enu_origin=ENU_ORIGIN, calibration=make_calibration()) as writer:
        write_scene(writer, np.random.default_rng(2))
    shutil.copytree(path, tmp_path / "by_zarr.zarr")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        zarr.consolidate_metadata(str(tmp_path / "by_zarr.zarr"))  # zarr's own walk of the store
    ours = json.loads((path / "zarr.json").read_bytes())
    assert ours == json.loads((tmp_path / "by_zarr.zarr/zarr.json").read_bytes())
    listed = ours["consolidated_metadata"]["metadata"]
    assert {"sar/left/image", "radar/right/cube", "lidar/top/points", "labels/moving_cars/x", "tracklog"} <= set(listed)


def _more_dtypes(rng: np.random.Generator) -> list[stores.NewArray]:
    return [
        stores.NewArray("a/u8", rng.integers(0, 255, 300).astype(np.uint8), (128,), stores.SMALL, {}),
        stores.NewArray("a/flag", rng.random(77) > 0.5, (77,), stores.SMALL, {}),
        stores.NewArray("a/i32", rng.integers(-5, 5, (40, 2)).astype(np.int32), (16, 2), stores.SMALL, {}),
        stores.NewArray("a/f32", rng.normal(size=(50, 4)).astype(np.float32), (50, 4), stores.FAST, {"k": 1.5}),
        stores.NewArray("a/big_endian", rng.normal(size=(9, 3)).astype(">f8"), (4, 3), stores.SMALL, {}),
        stores.NewArray("a/b/c/deep", np.arange(3, dtype=np.uint16), (3,), stores.SMALL, {}),
    ]


@pytest.mark.parametrize("make", [_arrays, _more_dtypes])
def test_the_files_made_without_zarr_are_zarrs_for_every_kind_and_dtype(tmp_path, make):
    """Chunks padded to the chunk shape, byte order, Blosc and zstd, bool and 1-byte types, parent groups."""
    from zendar_dataset.format import zarr_files

    staged = stores.create_store(tmp_path / "staged.zarr", "zarr")
    stores.write_arrays(staged.root, make(np.random.default_rng(7)))
    reference = stores.create_store(tmp_path / "reference.zarr", "zarr")
    arrays = make(np.random.default_rng(7))
    stores.fill_arrays(stores.create_arrays(reference.root, arrays), arrays)
    # Every array of these was made here, none handed to zarr.
    assert all(
        zarr_files.chunk_codec(stores._zarr_templates(a.data.dtype, a.data.ndim, a.kind)[0]) is not None for a in arrays
    )
    written, expected = _tree(tmp_path / "staged.zarr"), _tree(tmp_path / "reference.zarr")
    assert written.keys() == expected.keys()
    for key in expected:
        assert written[key] == expected[key], key
    opened = zarr.open_group(str(tmp_path / "staged.zarr"), mode="r")
    for a in make(np.random.default_rng(7)):
        np.testing.assert_array_equal(opened[a.path][...], a.data)


def test_codecs_not_made_here_are_written_by_zarr(tmp_path, monkeypatch):
    from zendar_dataset.format import zarr_files

    template = {"codecs": [{"name": "bytes", "configuration": {"endian": "little"}}, {"name": "gzip", "configuration": {"level": 1}}]}
    assert zarr_files.chunk_codec(template) is None
    assert zarr_files.chunk_codec({"codecs": [{"name": "transpose"}, {"name": "bytes"}]}) is None
    monkeypatch.setattr(zarr_files, "chunk_codec", lambda template: None)
    store = stores.create_store(tmp_path / "s.zarr", "zarr")
    stores.write_arrays(store.root, _arrays(np.random.default_rng(5)))
    reference = stores.create_store(tmp_path / "reference.zarr", "zarr")
    arrays = _arrays(np.random.default_rng(5))
    stores.fill_arrays(stores.create_arrays(reference.root, arrays), arrays)
    assert _tree(tmp_path / "s.zarr") == _tree(tmp_path / "reference.zarr")


def test_rows_written_straight_to_chunk_files_are_zarrs_bytes(tmp_path):
    """Lidar points in batches of whole chunks from a chunk boundary, the last chunk short and padded."""
    chunk = 1000
    rng = np.random.default_rng(3)
    points = rng.normal(size=(3 * chunk + 17, 4)).astype(np.float32)
    mine = stores.create_store(tmp_path / "mine.zarr", "zarr")
    reference = stores.create_store(tmp_path / "reference.zarr", "zarr")
    arrays = [
        stores.create_array(store.root, "lidar/top/points", shape=(0, 4), dtype=np.dtype(np.float32), chunks=(chunk, 4),
                            kind=stores.FAST, resizable=True)
        for store in (mine, reference)
    ]
    made: set[pathlib.Path] = set()
    for start, stop in ((0, 2 * chunk), (2 * chunk, points.shape[0])):
        arrays[0].resize((stop, 4))
        stores.write_rows(arrays[0], start, points[start:stop], made)
    arrays[1].resize(points.shape)
    arrays[1][...] = points  # zarr's own write
    assert _tree(tmp_path / "mine.zarr") == _tree(tmp_path / "reference.zarr")
    assert sorted(p.name for p in (tmp_path / "mine.zarr/lidar/top/points/c").iterdir()) == ["0", "1", "2", "3"]
    np.testing.assert_array_equal(zarr.open_array(str(tmp_path / "mine.zarr/lidar/top/points"), mode="r")[...], points)


def test_rows_not_on_a_chunk_boundary_go_through_zarr(tmp_path):
    store = stores.create_store(tmp_path / "s.zarr", "zarr")
    array = stores.create_array(store.root, "x", shape=(10, 2), dtype=np.dtype(np.float32), chunks=(4, 2), kind=stores.FAST, resizable=True)
    stores.write_rows(array, 3, np.ones((5, 2), np.float32), set())
    expected = np.zeros((10, 2), np.float32)
    expected[3:8] = 1
    np.testing.assert_array_equal(array[...], expected)


def test_rows_that_end_inside_a_chunk_keep_the_rows_after_them(tmp_path):
    store = stores.create_store(tmp_path / "s.zarr", "zarr")
    array = stores.create_array(store.root, "x", shape=(10, 2), dtype=np.dtype(np.float32), chunks=(4, 2), kind=stores.FAST, resizable=True)
    stores.write_rows(array, 0, np.full((10, 2), 7, np.float32), set())
    stores.write_rows(array, 4, np.ones((2, 2), np.float32), set())  # rows 6 and 7 of that chunk are kept
    expected = np.full((10, 2), 7, np.float32)
    expected[4:6] = 1
    np.testing.assert_array_equal(array[...], expected)
