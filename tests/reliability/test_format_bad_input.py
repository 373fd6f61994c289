"""Broken datasets give named problems, never tracebacks: a root that is a file, unreadable
dataset.json, corrupt array metadata (validate goes on listing the other problems), a corrupt
HDF5 chunk index and absurd claimed sizes.  In the library each is a ZendarFormatError."""

from __future__ import annotations

import json
import pathlib

import numpy as np
import pytest
import zarr

from tests.format.conftest import make_dataset, make_small_dataset
from tests.format.helpers import corrupt_chunk, crc32c_hex, reconsolidate, set_attr
from tests.reliability.outputs_helpers import assert_one_line_failure, run_in_process, run_tool
from zendar_dataset.errors import ZendarFormatError
from zendar_dataset.format import open_dataset
from zendar_dataset.format.validate import validate_dataset


@pytest.fixture(scope="module")
def zarr_template(tmp_path_factory) -> pathlib.Path:
    return make_small_dataset(tmp_path_factory.mktemp("template") / "ds", "zarr")


@pytest.fixture
def zarr_root(zarr_template, tmp_path) -> pathlib.Path:
    import shutil

    return pathlib.Path(shutil.copytree(zarr_template, tmp_path / "ds"))


@pytest.mark.parametrize(
    "command",
    [
        ["info", "{root}"],
        ["validate", "{root}"],
        ["export-gt", "{root}", "--split", "train", "-o", "{out}/gt.json"],
        ["convert", "{root}", "{out}/converted", "--to", "hdf5"],
    ],
    ids=["info", "validate", "export-gt", "convert"],
)
def test_a_root_that_is_a_file(tmp_path, command):
    readme = tmp_path / "README.md"
    readme.write_text("# not a dataset\n")
    args = [part.format(root=readme, out=tmp_path) for part in command]
    result = run_in_process("zendar-data", *args)
    if command[0] == "validate":
        assert result.returncode == 2 and "Traceback" not in result.stderr
        assert f"{readme}: expected a dataset root directory, found a file" in result.stdout
    else:
        assert_one_line_failure(result, 2, f"{readme}: expected a dataset root directory, found a file")
    with pytest.raises(ZendarFormatError, match="expected a dataset root directory, found a file"):
        open_dataset(readme)


def _not_utf8(path: pathlib.Path) -> None:
    path.write_bytes(b'{"format": "zendar-dataset", "name": "\xff\xfe"}')


def _directory(path: pathlib.Path) -> None:
    path.unlink()
    path.mkdir()


def _deep(path: pathlib.Path) -> None:
    path.write_text("[" * 100_000 + "]" * 100_000)


@pytest.mark.parametrize(
    ("breakage", "message"),
    [
        (_not_utf8, "dataset.json: expected UTF-8 text, found invalid start byte at byte 38"),
        (_directory, "dataset.json: expected a JSON file, found a directory"),
        (_deep, "dataset.json: expected JSON of reasonable depth, found nesting too deep to parse"),
    ],
    ids=["not-utf8", "a-directory", "nested-100k-levels"],
)
def test_unreadable_dataset_json(zarr_root, breakage, message):
    breakage(zarr_root / "dataset.json")
    with pytest.raises(ZendarFormatError, match=message):
        open_dataset(zarr_root)
    problems = validate_dataset(zarr_root)
    assert len(problems) == 1 and message in problems[0]
    assert_one_line_failure(run_in_process("zendar-data", "info", zarr_root), 2, message)


def _edit_metadata(scene: pathlib.Path, array_path: str, edit) -> None:
    path = scene / array_path / "zarr.json"
    text = path.read_text()
    path.write_text(edit(text))


def _with(**changes):
    return lambda text: json.dumps({**json.loads(text), **changes})


CORRUPT_METADATA = {
    "truncated": (lambda text: text[: len(text) // 2], "expected readable metadata, found JSONDecodeError"),
    "empty-object": (lambda text: "{}", "expected readable metadata, found MetadataValidationError"),
    "dtype-foo": (_with(data_type="foo"), "expected readable metadata, found ValueError: No Zarr data type found that matches 'foo'"),
    "negative-shape": (_with(shape=[-5, 16, 8, 4]), "expected readable metadata, found ValueError"),
    "zero-chunk": (
        _with(chunk_grid={"name": "regular", "configuration": {"chunk_shape": [0, 16, 8, 4]}}),
        "expected a chunk shape of positive sizes, found [0, 16, 8, 4]",
    ),
    "unknown-codec": (_with(codecs=[{"name": "nope"}]), "expected readable metadata, found UnknownCodecError"),
    "group-not-array": (
        lambda text: json.dumps({"zarr_format": 3, "node_type": "group", "attributes": {}}),
        "expected an array [N, any, any, any] complex64, found a group",
    ),
}


@pytest.mark.parametrize("case", list(CORRUPT_METADATA))
def test_corrupt_array_metadata_is_one_named_problem_among_the_others(zarr_root, case):
    edit, message = CORRUPT_METADATA[case]
    scene = zarr_root / "scenes" / "s0.zarr"
    set_attr(scene, "", "time_reference", "utc")  # an unrelated problem that must still be listed
    _edit_metadata(scene, "radar/left/cube", edit)
    problems = validate_dataset(zarr_root)
    assert any(p.startswith("s0: radar/left/cube: ") and message in p for p in problems), problems
    assert "s0: /: expected attribute time_reference 'gps', found 'utc'" in problems
    # The sibling radar and the other streams are still checked and read.
    assert not any(p.startswith(("s0: radar/right", "s0: sar/", "s0: lidar/")) for p in problems), problems
    with pytest.raises(ZendarFormatError) as info:
        open_dataset(zarr_root).open_scene("s0")
    assert any(message in p for p in info.value.problems)
    result = run_in_process("zendar-data", "validate", zarr_root)
    assert result.returncode == 2 and "Traceback" not in result.stderr


@pytest.fixture(scope="module")
def scenes_template(tmp_path_factory) -> pathlib.Path:
    """Four valid zarr scenes; s0's labels also carry the optional field num_radar_scatterers."""
    root = make_dataset(tmp_path_factory.mktemp("scenes") / "ds", "zarr")
    scene = root / "scenes" / "s0.zarr"
    values = np.array([3, 5], dtype=np.int64)  # one per label of s0
    node = zarr.open_group(str(scene), mode="a").create_array(
        "labels/moving_cars/num_radar_scatterers", shape=values.shape, dtype=values.dtype, chunks=values.shape
    )
    node[...] = values
    node.attrs["chunk_crc32c"] = crc32c_hex(values, values.shape[0])
    reconsolidate(scene)
    assert validate_dataset(root) == []
    return root


_UNKNOWN_DTYPE = (_with(data_type="foo"), "ValueError: No Zarr data type found that matches 'foo'")
_UNKNOWN_FORMAT = (_with(zarr_format=7), "ValueError: Invalid zarr_format. Expected one of 2 or 3. Got 7.")
UNREADABLE_METADATA = {
    "lidar/top/points": _UNKNOWN_DTYPE,
    "labels/moving_cars/num_radar_scatterers": _UNKNOWN_DTYPE,  # an optional field
    "radar/left/cube": _UNKNOWN_DTYPE,
    "radar/left": _UNKNOWN_FORMAT,  # a sensor's group, whose arrays the schema checks open directly
    "labels": _UNKNOWN_FORMAT,
}


@pytest.mark.parametrize("node_path", list(UNREADABLE_METADATA))
def test_unreadable_metadata_is_one_problem_naming_the_scene_and_validate_goes_on(scenes_template, tmp_path, node_path):
    import shutil

    edit, found = UNREADABLE_METADATA[node_path]
    root = pathlib.Path(shutil.copytree(scenes_template, tmp_path / "ds"))
    _edit_metadata(root / "scenes" / "s0.zarr", node_path, edit)
    corrupt_chunk(root / "scenes" / "s1.zarr", "sar/left/image", 1)  # an independent problem in another scene
    problems = validate_dataset(root)
    # Exactly these two: the other arrays of s0 and the scenes s2, s3 were checked and are valid.
    assert len(problems) == 2, problems
    assert problems[0] == f"s0: {node_path}: expected readable metadata, found {found}"
    assert problems[1].startswith("s1: sar/left/image: chunk [1, 0, 0]: expected a readable chunk"), problems
    result = run_in_process("zendar-data", "validate", root)
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert result.stdout.splitlines() == problems
    assert result.stderr == f"{root}: 2 format violation(s)\n"
    # convert refuses the same store with the same words.
    result = run_in_process("zendar-data", "convert", root, tmp_path / "out", "--to", "hdf5")
    assert_one_line_failure(result, 2, problems[0])


def test_a_claimed_length_of_ten_to_the_fifteen(zarr_root):
    scene = zarr_root / "scenes" / "s0.zarr"
    _edit_metadata(scene, "radar/left/timestamp_ns", _with(shape=[10**15]))
    problems = validate_dataset(zarr_root)
    assert problems[0] == (
        "s0: radar/left/timestamp_ns: expected a plausible size (at most 16777216 chunks and 1099511627776 bytes), "
        "found shape [1000000000000000] in 250000000000000 chunks (8000000000000000 bytes); the metadata is likely corrupt"
    )
    with pytest.raises(ZendarFormatError, match="radar/left/timestamp_ns: expected a plausible size"):
        open_dataset(zarr_root).open_scene("s0")


def test_a_corrupt_hdf5_chunk_index(tmp_path):
    root = make_small_dataset(tmp_path / "ds", "hdf5")
    path = root / "scenes" / "s0.h5"
    data = bytearray(path.read_bytes())
    # Version-1 B-tree nodes ("TREE") index the chunks of every chunked array of the file.
    trees = [i for i in range(len(data)) if data.startswith(b"TREE", i) and data[i + 4] == 1]  # type 1: chunks
    assert trees, "expected v1 B-tree chunk indices in the file"
    for start in trees:
        data[start + 8 : start + 88] = b"\xee" * 80  # sibling addresses, keys and chunk addresses
    path.write_bytes(bytes(data))
    problems = validate_dataset(root)
    assert "s0: radar/left/cube: expected a readable chunk index, found RuntimeError: Can't get number of chunks" in "\n".join(problems)
    assert all(p.startswith("s0: ") and "expected a readable chunk index" in p for p in problems), problems
    result = run_in_process("zendar-data", "validate", root)
    assert result.returncode == 2 and "Traceback" not in result.stderr
    scene = open_dataset(root).open_scene("s0")  # metadata only: the index is read with the data
    with pytest.raises(ZendarFormatError, match="s0: radar/left/cube: expected readable complex64 chunks, found a truncated or corrupt chunk"):
        scene.array("radar/left/cube")[1]
