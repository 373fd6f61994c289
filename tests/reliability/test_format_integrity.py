"""Silent corruption is caught: every chunk's checksum is recorded when written, verified by
``validate`` (every mismatch, named by scene, array and chunk) and by the loader on request;
missing chunks follow the Zarr v3 rule exactly as docs/format.md states it.  The promise is every
value as written: a stored byte that changes no value passes, as the README and docs/format.md say."""

from __future__ import annotations

import pathlib
import warnings

import h5py
import numpy as np
import pytest
import zarr

from tests.format.conftest import CAM_H, CAM_W, A, D, R, make_small_dataset
from tests.format.helpers import dump
from zendar_dataset import ZendarDataset
from zendar_dataset.errors import ZendarFormatError
from zendar_dataset.format import open_dataset
from zendar_dataset.format.convert import convert_dataset
from zendar_dataset.format.validate import NO_CHECKSUMS_NOTE, validate_dataset

SUFFIX = {"zarr": ".zarr", "hdf5": ".h5"}


def _scene(root: pathlib.Path, backend: str) -> pathlib.Path:
    return root / "scenes" / f"s0{SUFFIX[backend]}"


def overwrite_4_bytes(scene: pathlib.Path, array_path: str, chunk: tuple[int, ...]) -> None:
    """Invert 4 stored bytes in the middle of one chunk (its file in zarr, its byte range in HDF5)."""
    if scene.suffix == ".zarr":
        path = scene / array_path / "c" / "/".join(map(str, chunk))
        offset, size = 0, path.stat().st_size
    else:
        with h5py.File(scene, "r") as handle:
            dataset = handle[array_path]
            info = dataset.id.get_chunk_info_by_coord(tuple(i * c for i, c in zip(chunk, dataset.chunks)))
        path, offset, size = scene, int(info.byte_offset), int(info.size)
    with open(path, "r+b") as raw:
        raw.seek(offset + size // 2)
        original = raw.read(4)
        raw.seek(offset + size // 2)
        raw.write(bytes(b ^ 0xFF for b in original))


@pytest.mark.parametrize("backend", ["zarr", "hdf5"])
@pytest.mark.parametrize(
    ("array_path", "chunk"),
    [("radar/left/cube", (2, 0, 0, 0)), ("lidar/top/points", (0, 0))],
    ids=["raw-radar-cube", "compressed-lidar-points"],
)
def test_four_changed_bytes_fail_validate_and_the_verifying_loader(tmp_path, backend, array_path, chunk):
    root = make_small_dataset(tmp_path / "ds", backend)
    assert validate_dataset(root) == []
    overwrite_4_bytes(_scene(root, backend), array_path, chunk)
    problems = validate_dataset(root)
    assert len(problems) == 1, problems
    # Either the values changed (checksum) or the compressed stream no longer decodes: both name the chunk.
    assert problems[0].startswith(f"s0: {array_path}: chunk {list(chunk)}: ")
    assert "corrupt" in problems[0]
    scene = open_dataset(root).open_scene("s0", verify_checksums=True)
    # A compressed chunk that no longer decodes is reported as such; one that does, by its checksum.
    named = rf"s0: {array_path}: (chunk \[{', '.join(map(str, chunk))}\]|expected readable float32 chunks)"
    with pytest.raises(ZendarFormatError, match=named):
        if array_path == "radar/left/cube":
            scene.array(array_path)[2]
        else:
            scene.lidar_points("top", 0)
    if array_path == "radar/left/cube":
        scene.array(array_path)[1]  # the other chunks verify
        with pytest.raises(ZendarFormatError, match=r"chunk \[2, 0, 0, 0\]"):
            scene.array(array_path)[1:3, 0]  # a partial read still verifies whole chunks


def test_verify_checksums_in_the_torch_dataset(tmp_path):
    root = make_small_dataset(tmp_path / "ds", "hdf5")
    overwrite_4_bytes(_scene(root, "hdf5"), "sar/left/image", (1, 0, 0))
    plain = ZendarDataset(root, "train", streams=("sar",))
    item = plain[1]  # the fast path hashes nothing: the changed values come back
    assert item["sar"]["left"]["image"].shape[0] > 0
    checked = ZendarDataset(root, "train", streams=("sar",), verify_checksums=True)
    checked[0]
    with pytest.raises(ZendarFormatError, match=r"s0: sar/left/image: chunk \[1, 0, 0\]: expected crc32c"):
        checked[1]


def test_validate_lists_every_mismatch_at_once(tmp_path):
    root = make_small_dataset(tmp_path / "ds", "zarr")
    scene = _scene(root, "zarr")
    for frame in (0, 3):
        overwrite_4_bytes(scene, "radar/right/cube", (frame, 0, 0, 0))
    overwrite_4_bytes(scene, "sar/right/image", (1, 0, 0))
    problems = validate_dataset(root)
    assert [p.split(": expected")[0] for p in problems] == [
        "s0: radar/right/cube: chunk [0, 0, 0, 0]",
        "s0: radar/right/cube: chunk [3, 0, 0, 0]",
        "s0: sar/right/image: chunk [1, 0, 0]",
    ]


@pytest.mark.parametrize(("source", "target"), [("zarr", "hdf5"), ("hdf5", "zarr")])
def test_convert_carries_checksums_and_refuses_a_corrupt_source(tmp_path, source, target):
    root = make_small_dataset(tmp_path / "src", source)
    out = convert_dataset(root, tmp_path / "out", target)
    assert validate_dataset(out) == []
    # Checksums cover decoded values, so they are equal across backends and compressors.
    original_attrs, converted_attrs = dump(_scene(root, source))[1], dump(_scene(out, target))[1]
    assert {k: v.get("chunk_crc32c") for k, v in converted_attrs.items()} == {
        k: v.get("chunk_crc32c") for k, v in original_attrs.items()
    }
    overwrite_4_bytes(_scene(root, source), "radar/left/cube", (1, 0, 0, 0))
    with pytest.raises(ZendarFormatError, match=r"s0: radar/left/cube: chunk \[1, 0, 0, 0\]: .* the source is corrupt"):
        convert_dataset(root, tmp_path / "again", target)
    assert not (tmp_path / "again").exists()


REPOSITORY = pathlib.Path(__file__).resolve().parents[2]


def _level(line: str) -> int:
    """A Markdown heading's level (``## …`` is 2); 0 for other lines."""
    return len(line) - len(line.lstrip("#")) if line.startswith("#") else 0


def _section(path: pathlib.Path, heading: str) -> str:
    """The text of ``path`` under ``heading`` up to the next heading as high, on one line."""
    lines = path.read_text(encoding="utf-8").splitlines()
    start = lines.index(heading)
    end = next((i for i in range(start + 1, len(lines)) if 0 < _level(lines[i]) <= _level(heading)), len(lines))
    return " ".join(" ".join(lines[start + 1 : end]).split())


def test_the_checksum_promise_is_every_value_as_written(tmp_path):
    """A changed stored byte that changes no value (the padding of an edge chunk beyond the array's
    bounds) passes validate, the verifying loader and convert; the README and docs/format.md say
    what is guaranteed exactly: every value as written, not every byte, and why."""
    root = make_small_dataset(tmp_path / "ds", "zarr")
    array_path = "lidar/top/points"  # fewer rows than one chunk of 65 536, compressed
    stored = zarr.open_array(str(_scene(root, "zarr") / array_path), mode="r")
    values = stored[...]
    n_rows, chunk_rows = values.shape[0], stored.chunks[0]
    assert n_rows < chunk_rows
    # The same chunk encoded by the same codecs, with values in the padding where the writer put zeros.
    twin = zarr.create_array(
        str(tmp_path / "twin.zarr"), shape=stored.chunks, chunks=stored.chunks, dtype=stored.dtype,
        serializer=stored.serializer, compressors=stored.compressors, fill_value=stored.fill_value,
    )
    padded = np.full(stored.chunks, 7.0, dtype=stored.dtype)
    padded[:n_rows] = values
    twin[...] = padded
    key = pathlib.Path("c", *["0"] * stored.ndim)
    chunk = _scene(root, "zarr") / array_path / key
    written = chunk.read_bytes()
    chunk.write_bytes((tmp_path / "twin.zarr" / key).read_bytes())
    assert chunk.read_bytes() != written
    np.testing.assert_array_equal(zarr.open_array(str(_scene(root, "zarr") / array_path), mode="r")[...], values)
    assert validate_dataset(root) == []
    with open_dataset(root).open_scene("s0", verify_checksums=True) as scene:
        np.testing.assert_array_equal(scene.array(array_path)[:], values)
    convert_dataset(root, tmp_path / "converted", "hdf5")

    promise = _section(REPOSITORY / "README.md", "## Reliability")
    assert "every byte" not in promise
    assert "passes has every value of every chunk as written" in promise
    assert "a changed stored byte that changes no value" in promise
    checksums = _section(REPOSITORY / "docs" / "format.md", "### Chunk checksums (a backward-compatible addition to format v1)")
    assert "every value as written, not every stored byte" in checksums
    assert "padding" in checksums and "`zendar-data convert`" in checksums


def _rewrite_with_plain_zarr(scene: pathlib.Path, zero_frames: dict[str, int]) -> None:
    """Rewrite a scene as zarr-python does by default: chunks equal to the fill value are not
    stored, and no checksums.  ``zero_frames``: array path -> frame set to zeros first."""
    arrays, attrs = dump(scene)
    for name, frame in zero_frames.items():
        arrays[name][frame] = 0
    plain = scene.with_name("plain.zarr")
    group = zarr.open_group(str(plain), mode="w", zarr_format=3)
    group.attrs.update({k: v for k, v in attrs[""].items() if k != "chunk_checksums"})
    for name, data in arrays.items():
        frame_chunked = name.endswith(("cube", "image"))
        chunks = (1, *data.shape[1:]) if frame_chunked else data.shape
        # Raw cubes as the reference writer stores them, so the direct fast path reads them.
        compressors = None if name.endswith("cube") else "auto"
        array = group.create_array(name, shape=data.shape, dtype=data.dtype, chunks=chunks, compressors=compressors, fill_value=0)
        array[...] = data
        array.attrs.update({k: v for k, v in attrs[name].items() if k != "chunk_crc32c"})
    for name, value in attrs.items():
        if name and name not in arrays:
            group.require_group(name).attrs.update(value)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        zarr.consolidate_metadata(str(plain))
    import shutil

    shutil.rmtree(scene)
    plain.rename(scene)


def test_store_without_checksums_reads_missing_chunks_as_fill_value(tmp_path):
    root = make_small_dataset(tmp_path / "ds", "zarr")
    scene = _scene(root, "zarr")
    expected = dump(scene)[0]
    _rewrite_with_plain_zarr(scene, {"radar/left/cube": 2, "camera/front/image": 1})
    assert not (scene / "radar/left/cube/c/2/0/0/0").exists() and not (scene / "camera/front/image/c/1/0/0/0").exists()
    notes: list[str] = []
    assert validate_dataset(root, notes=notes) == []
    assert notes == [f"s0: {NO_CHECKSUMS_NOTE}"]
    reader = open_dataset(root).open_scene("s0")
    assert not reader.records_checksums
    cube = reader.array("radar/left/cube")
    assert cube._direct is not None  # the fast path is the one under test
    assert np.count_nonzero(cube[2]) == 0 and cube[1].tobytes() == expected["radar/left/cube"][1].tobytes()
    assert np.count_nonzero(reader.array("camera/front/image")[1]) == 0
    batch = np.empty((2, R, D, A), np.complex64)
    cube.read_into(1, 3, batch)
    assert batch[0].tobytes() == expected["radar/left/cube"][1].tobytes() and np.count_nonzero(batch[1]) == 0
    item = ZendarDataset(root, "train", streams=("radar", "camera"), reference="radar/left")[2]
    assert np.count_nonzero(np.asarray(item["radar"]["left"]["cube"])) == 0
    assert item["camera"]["front"]["image"].shape == (CAM_H, CAM_W, 3)


def test_store_with_checksums_refuses_a_missing_chunk_everywhere(tmp_path):
    root = make_small_dataset(tmp_path / "ds", "zarr")
    scene = _scene(root, "zarr")
    (scene / "radar/left/cube/c/2/0/0/0").unlink()
    (scene / "lidar/top/points/c/0/0").unlink()
    problems = validate_dataset(root)
    assert problems == [
        "s0: radar/left/cube: expected every chunk stored (the store records checksums), found 1 missing: chunk [2, 0, 0, 0]",
        "s0: lidar/top/points: expected every chunk stored (the store records checksums), found 1 missing: chunk [0, 0]",
    ]
    reader = open_dataset(root).open_scene("s0")
    with pytest.raises(ZendarFormatError, match="s0: radar/left/cube: .*chunk of frame 2 is missing"):
        reader.array("radar/left/cube")[2]
    with pytest.raises(ZendarFormatError, match=r"s0: lidar/top/points: expected every chunk stored .* chunk \[0, 0\] missing"):
        reader.lidar_points("top", 1)


@pytest.mark.parametrize("checksummed", [True, False], ids=["with-checksums", "without-checksums"])
def test_two_chunks_per_frame_with_one_missing_is_refused_by_reader_and_validate(tmp_path, checksummed):
    root = make_small_dataset(tmp_path / "ds", "zarr")
    scene = _scene(root, "zarr")
    if not checksummed:
        _rewrite_with_plain_zarr(scene, {})
    cube = dump(scene)[0]["radar/left/cube"]
    group = zarr.open_group(str(scene), mode="a", use_consolidated=False)
    del group["radar/left/cube"]
    array = group.create_array("radar/left/cube", shape=cube.shape, dtype=cube.dtype, chunks=(1, R // 2, D, A), compressors=None)
    array[...] = cube
    (scene / "radar/left/cube/c/1/1/0/0").unlink()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        zarr.consolidate_metadata(str(scene))
    message = f"s0: radar/left/cube: expected one chunk per frame [1, {R}, {D}, {A}], found chunks [1, {R // 2}, {D}, {A}]"
    assert message in validate_dataset(root)
    with pytest.raises(ZendarFormatError) as info:
        open_dataset(root).open_scene("s0")
    assert message in info.value.problems


@pytest.mark.parametrize("backend", ["zarr", "hdf5"])
def test_the_default_read_path_hashes_nothing(tmp_path, backend, monkeypatch):
    root = make_small_dataset(tmp_path / "ds", backend)
    calls = []
    monkeypatch.setattr("zendar_dataset.format.checksums.crc32c", lambda values: calls.append(values.shape) or 0)
    dataset = ZendarDataset(root, "train", streams=("radar", "sar", "camera", "lidar", "tracklog"))
    for index in range(len(dataset)):
        dataset[index]
    assert calls == []
    with pytest.raises(ZendarFormatError, match=r"s0: radar/left/timestamp_ns: chunk \[0\]: expected crc32c"):
        ZendarDataset(root, "train", streams=("radar",), verify_checksums=True)  # every checksum now reads as 0
    assert calls
